"""Scan design for scanning lidars, by optimisation through the retrievals' error models.

**Dual-Doppler** (`design_dual_doppler`): two scanning lidars' positions (and heights) for the
smallest retrieval variance of the horizontal wind ``(u, v)`` at target points. Each lidar's
LOS carries independent noise of standard deviation `sigma` (m/s); the retrieval is
`lidarjax.dual_doppler`'s 2x2 solve (``w`` assumed), whose sensitivities to the two LOS
``d(u, v) / d(los_a, los_b)`` (exact, `jax.jacfwd` of the solve at the crossing geometry of
`lidarjax.crossing_geometry`) give per point ``var(u) + var(v) = sigma^2 sum_j |d(u, v) /
d los_j|^2``; for level beams crossing at ``beta`` this is ``2 sigma^2 / sin^2 beta``, smallest
at 90 degrees. The objective is its weighted mean over the points (m^2/s^2). Each lidar's
location is a decision variable in a `lidarjax.RegionBox` or a `RegionRing` (a bearing at a
fixed distance from a centre).

**VAD** (`design_vad`): the elevation (continuous) and ray count (discrete: every count of
`n_rays` is tried) of a full-turn PPI/VAD whose `lidarjax.vad_fit` gives the smallest variance
of ``(u, v)`` at the given heights. The gate of height ``h`` is at range ``h / sin(e)``; the
LOS noise of a ray is ``sigma (range / range_ref)^range_exponent`` (the carrier-to-noise ratio
falling with range), times ``sqrt(1 / accumulation)`` (s) when a `scan_time` is given (each of
``n`` rays then accumulates ``scan_time / n - move_time``). The variance per height is
``sum_r sigma_r^2 |d(u, v) / d los_r|^2`` with the exact sensitivities of `vad_fit` (for ``n``
evenly spaced rays and equal noise: ``4 sigma^2 / (n cos^2 e)``). Ray counts are padded to the
largest with rays the fit does not use (NaN LOS), so every count runs the same compiled program.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..mount import Mount
from ..scanning.dual import _dual, _geometry
from ..scanning.profiles import _vad
from . import _search
from .placement import RegionBox, box_location

__all__ = ["RegionRing", "DualDopplerDesign", "design_dual_doppler", "dual_doppler_variance",
           "VadDesign", "design_vad", "vad_variance"]


@dataclasses.dataclass(frozen=True)
class RegionRing:
    """Locations at a fixed horizontal `distance` (m) from `centre` ``(x, y)`` (CFD metres),
    at height `z` (m); the decision variable is the bearing (degrees clockwise from ``+y``)
    within `bearing` ``(low, high)``."""

    centre: tuple[float, float]
    distance: float
    z: float = 0.0
    bearing: tuple[float, float] = (0.0, 360.0)

    def __post_init__(self):
        c = np.asarray(self.centre, np.float64)
        b = np.asarray(self.bearing, np.float64)
        if c.shape != (2,) or not np.all(np.isfinite(c)):
            raise ValueError(f"RegionRing: `centre` must be (x, y) CFD metres, got {self.centre!r}.")
        if not (np.isfinite(self.distance) and self.distance > 0):
            raise ValueError(f"RegionRing: `distance` must be > 0 m, got {self.distance!r}.")
        if not np.isfinite(self.z):
            raise ValueError(f"RegionRing: `z` must be finite, got {self.z!r}.")
        if b.shape != (2,) or not np.all(np.isfinite(b)) or not b[1] > b[0]:
            raise ValueError(f"RegionRing: `bearing` must be (low, high) degrees with low < high, "
                             f"got {self.bearing!r}.")

    free = (0,)
    names = ("bearing",)

    def bounds(self):
        return np.asarray(self.bearing[:1]), np.asarray(self.bearing[1:])


def _region_location(region, x):
    if isinstance(region, RegionRing):
        b = jnp.deg2rad(x[0])
        c = jnp.asarray(region.centre, x.dtype)
        return jnp.stack([c[0] + region.distance * jnp.sin(b),
                          c[1] + region.distance * jnp.cos(b), jnp.asarray(region.z, x.dtype)])
    return box_location(region.lo, region.free, x)


class _DualProblem(eqx.Module):
    points: Array
    weights: Array
    sigma: Array
    w: Array
    region_a: object = eqx.field(static=True)
    region_b: object = eqx.field(static=True)
    n_a: int = eqx.field(static=True)


def _point_variance(na, nb, w, sigma):
    """``var(u) + var(v)`` of `dual_doppler`'s solve for unit directions ``(3,)``."""
    def solve(los):
        uv = _dual(los[0:1], los[1:2], na[None], nb[None], w[None]).velocity[0, :2]
        return uv, uv

    # (2 components, 2 LOS); the solve is NaN (its derivative 0) for parallel beams
    jac, uv = jax.jacfwd(solve, has_aux=True)(jnp.zeros(2, na.dtype))
    return jnp.where(jnp.all(jnp.isfinite(uv)), sigma**2 * jnp.sum(jac**2), jnp.nan)


def dual_doppler_variance(location_a: Float[ArrayLike, 3], location_b: Float[ArrayLike, 3],
                          points: Float[ArrayLike, "p 3"], *, sigma: float = 1.0,
                          w: float = 0.0) -> Float[Array, " p"]:
    """``var(u) + var(v)`` (m^2/s^2) of the dual-Doppler retrieval at `points` (CFD metres)
    from lidars at `location_a`, `location_b` with LOS noise `sigma` (m/s) (module docs);
    NaN where the beams are parallel or a lidar stands on a point."""
    pts = jnp.atleast_2d(jnp.asarray(points, jnp.result_type(float)))
    return _variance_jit(jnp.asarray(location_a, pts.dtype), jnp.asarray(location_b, pts.dtype),
                         pts, jnp.asarray(sigma, pts.dtype), jnp.asarray(w, pts.dtype))


@jax.jit
def _variance_jit(la, lb, pts, sigma, w):
    geo = _geometry(Mount(la), Mount(lb), pts)
    return jax.vmap(lambda a, b: _point_variance(a, b, w, sigma))(geo.direction_a,
                                                                 geo.direction_b)


def _dual_objective(pb: _DualProblem, x):
    la = _region_location(pb.region_a, x[:pb.n_a])
    lb = _region_location(pb.region_b, x[pb.n_a:])
    geo = _geometry(Mount(la), Mount(lb), pb.points)
    var = jax.vmap(lambda a, b: _point_variance(a, b, pb.w, pb.sigma))(geo.direction_a,
                                                                      geo.direction_b)
    ok = jnp.isfinite(var) & (geo.range_a > 0) & (geo.range_b > 0)
    value = jnp.sum(pb.weights * jnp.where(ok, var, 0.0))
    used = pb.weights > 0
    feasible = jnp.all(ok | ~used) & jnp.isfinite(value)
    return value, feasible, (la, lb, geo.crossing_angle, var)


class DualDopplerDesign(eqx.Module):
    """Result of `design_dual_doppler`: `names` and `x` the decision variables at the
    optimum (m, or degrees of bearing), `location_a`, `location_b` ``(3,)`` CFD metres,
    `value` the weighted mean ``var(u) + var(v)`` (m^2/s^2) and its `gradient`, per point
    `variance` ``(p,)`` and `crossing_angle` ``(p,)`` degrees, `start`/`start_value`,
    `path`/`path_values` of the winning local search, `n_evaluations`, `feasible`,
    `converged` and `message`."""

    names: tuple = eqx.field(static=True)
    x: np.ndarray
    location_a: np.ndarray
    location_b: np.ndarray
    value: float
    gradient: np.ndarray
    variance: np.ndarray
    crossing_angle: np.ndarray
    start: np.ndarray
    start_value: float
    path: np.ndarray
    path_values: np.ndarray
    n_evaluations: int
    feasible: bool
    converged: bool
    message: str = eqx.field(static=True)


def _check_region(fname, name, region):
    if not isinstance(region, RegionBox | RegionRing):
        raise ValueError(f"{fname}: `{name}` must be a lidarjax.RegionBox or "
                         f"lidarjax.design.RegionRing, got {type(region).__name__}.")


def design_dual_doppler(
    points: Float[ArrayLike, "p 3"],
    region_a: RegionBox | RegionRing,
    region_b: RegionBox | RegionRing,
    *,
    weights: Float[ArrayLike, " p"] | None = None,
    sigma: float = 1.0,
    w: float = 0.0,
    n_coarse: int = 256,
    n_starts: int = 4,
    solver=None,
    max_steps: int = 60,
) -> DualDopplerDesign:
    """Positions of two scanning lidars for the smallest dual-Doppler retrieval variance at
    target `points` ``(p, 3)`` (CFD metres; module docs).

    **Arguments:**

    - `region_a`, `region_b`: where each lidar may stand (`lidarjax.RegionBox`: a free
      ``z`` is the lidar's height; `RegionRing`: a bearing at a fixed distance).
    - `weights`: ``(p,)`` importance of each point (normalised), uniform by default.
    - `sigma`: each LOS's noise standard deviation, m/s; `w`: vertical wind assumed, m/s.
    - `n_coarse`, `n_starts`, `solver`, `max_steps`: the search (as `design_placement`).

    **Returns:** a `DualDopplerDesign`. Raises `ValueError` before compiling for bad points,
    regions or weights; no feasible pair (parallel beams everywhere) gives ``feasible=False``.
    """
    fname = "design_dual_doppler"
    pts = np.atleast_2d(np.asarray(points, np.float64))
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0 or not np.all(np.isfinite(pts)):
        raise ValueError(f"{fname}: `points` must be (p, 3) finite CFD metres, got shape "
                         f"{pts.shape}.")
    _check_region(fname, "region_a", region_a)
    _check_region(fname, "region_b", region_b)
    p = pts.shape[0]
    wts = np.ones(p) if weights is None else np.asarray(weights, np.float64).ravel()
    if wts.shape != (p,) or not np.all(np.isfinite(wts)) or np.any(wts < 0) or not wts.sum() > 0:
        raise ValueError(f"{fname}: `weights` must be {p} finite values >= 0, not all 0.")
    if not (np.isfinite(sigma) and sigma > 0):
        raise ValueError(f"{fname}: `sigma` must be > 0 m/s, got {sigma!r}.")
    _search.check_counts(fname, n_coarse=n_coarse, n_starts=n_starts, max_steps=max_steps)
    dtype = jnp.result_type(float)
    lo_a, hi_a = region_a.bounds()
    lo_b, hi_b = region_b.bounds()
    lo = jnp.asarray(np.concatenate([lo_a, lo_b]), dtype)
    hi = jnp.asarray(np.concatenate([hi_a, hi_b]), dtype)
    names = tuple(f"{n}_a" for n in region_a.names) + tuple(f"{n}_b" for n in region_b.names)
    pb = _DualProblem(jnp.asarray(pts, dtype), jnp.asarray(wts / wts.sum(), dtype),
                      jnp.asarray(sigma, dtype), jnp.asarray(w, dtype), region_a, region_b,
                      len(region_a.names))
    res = _search.search(_dual_objective, pb, lo, hi, n_coarse=n_coarse, n_starts=n_starts,
                         solver=_search.default_solver(dtype) if solver is None else solver,
                         max_steps=max_steps, batch_size=256)
    n_eval = int(res["n_evaluations"])
    if not res["feasible"]:
        nan = np.full(len(names), np.nan)
        return DualDopplerDesign(names, nan, np.full(3, np.nan), np.full(3, np.nan), np.nan,
                                 nan, np.full(p, np.nan), np.full(p, np.nan), nan, np.nan,
                                 np.zeros((0, len(names))), np.zeros(0), n_eval, False, False,
                                 "no feasible pair of positions (parallel beams or a lidar on "
                                 "a target everywhere); no optimum")
    la, lb, crossing, var = res["aux"]
    return DualDopplerDesign(names, res["x"], np.asarray(la), np.asarray(lb), res["value"],
                             np.asarray(res["gradient"]), np.asarray(var), np.asarray(crossing),
                             res["start"], res["start_value"], res["path"], res["path_values"],
                             n_eval, True, bool(res["converged"]),
                             _search.message(bool(res["converged"])))


# ------------------------------------------------------------------------------------------
# VAD


class _VadProblem(eqx.Module):
    heights: Array
    n_rays: Array  # the ray count (dynamic)
    sigma: Array
    range_ref: Array
    range_exponent: Array
    scan_time: Array
    move_time: Array
    max_rays: int = eqx.field(static=True)
    timed: bool = eqx.field(static=True)


def _vad_var(pb: _VadProblem, elevation):
    i = jnp.arange(pb.max_rays)
    used = i < pb.n_rays
    az = 360.0 * i / pb.n_rays
    ranges = pb.heights / jnp.sin(jnp.deg2rad(elevation))
    el = jnp.broadcast_to(elevation, az.shape)

    def fit(los):
        los = jnp.where(used[:, None], los, jnp.nan)
        return _vad(los, az, el, ranges).velocity[..., :2]  # (g, 2)

    zeros = jnp.zeros((pb.max_rays, pb.heights.shape[0]), pb.heights.dtype)
    jac = jax.jacfwd(fit)(zeros)  # (g, 2, r, g)
    g = pb.heights.shape[0]
    jac = jac[jnp.arange(g), :, :, jnp.arange(g)]  # (g, 2, r): each height's own gate
    sig = pb.sigma * (ranges / pb.range_ref) ** pb.range_exponent  # (g,)
    accumulation = pb.scan_time / pb.n_rays - pb.move_time
    if pb.timed:
        sig = sig / jnp.sqrt(jnp.where(accumulation > 0, accumulation, 1.0))
    var = jnp.sum(jnp.where(used[None, None, :], jac, 0.0) ** 2, axis=(1, 2)) * sig**2
    ok = jnp.all(jnp.isfinite(var)) & ((accumulation > 0) | (not pb.timed))
    return var, ok


def _vad_objective(pb: _VadProblem, x):
    var, ok = _vad_var(pb, x[0])
    value = jnp.mean(var)
    return value, ok & jnp.isfinite(value), var


def vad_variance(elevation: float, n_rays: int, heights: Float[ArrayLike, " g"], *,
                 sigma: float = 0.1, range_ref: float = 100.0, range_exponent: float = 0.0,
                 scan_time: float | None = None, move_time: float = 0.0) -> Float[Array, " g"]:
    """``var(u) + var(v)`` (m^2/s^2) per height of `vad_fit` for `n_rays` evenly spaced rays
    at `elevation` degrees (noise model in the module docs)."""
    pb = _vad_problem("vad_variance", heights, [n_rays], sigma, range_ref, range_exponent,
                      scan_time, move_time)
    pb = eqx.tree_at(lambda q: q.n_rays, pb, jnp.asarray(float(n_rays), pb.heights.dtype))
    return _vad_var_jit(pb, jnp.asarray(elevation, pb.heights.dtype))[0]


_vad_var_jit = eqx.filter_jit(_vad_var)


def _vad_problem(fname, heights, n_rays, sigma, range_ref, range_exponent, scan_time, move_time):
    h = np.atleast_1d(np.asarray(heights, np.float64))
    if h.ndim != 1 or h.size == 0 or not np.all(np.isfinite(h)) or np.any(h <= 0):
        raise ValueError(f"{fname}: `heights` must be positive finite metres, got {heights!r}.")
    counts = [int(n) for n in np.atleast_1d(n_rays)]
    if not counts or any(n != m or n < 3 for n, m in zip(counts, np.atleast_1d(n_rays),
                                                        strict=True)):
        raise ValueError(f"{fname}: `n_rays` must be integers >= 3 (a VAD fits three "
                         f"components), got {n_rays!r}.")
    for name, val in (("sigma", sigma), ("range_ref", range_ref)):
        if not (np.isfinite(val) and val > 0):
            raise ValueError(f"{fname}: `{name}` must be > 0, got {val!r}.")
    if not np.isfinite(range_exponent):
        raise ValueError(f"{fname}: `range_exponent` must be finite, got {range_exponent!r}.")
    timed = scan_time is not None
    if timed and not (np.isfinite(scan_time) and scan_time > 0):
        raise ValueError(f"{fname}: `scan_time` must be > 0 s, got {scan_time!r}.")
    if not (np.isfinite(move_time) and move_time >= 0):
        raise ValueError(f"{fname}: `move_time` must be >= 0 s, got {move_time!r}.")
    dt = jnp.result_type(float)
    f = lambda v: jnp.asarray(v, dt)  # noqa: E731
    return _VadProblem(f(h), f(counts[0]), f(sigma), f(range_ref), f(range_exponent),
                       f(scan_time if timed else 1.0), f(move_time), max(counts), timed)


class VadDesign(eqx.Module):
    """Result of `design_vad`: the best `elevation` (degrees) and `n_rays`, `value` the mean
    over heights of ``var(u) + var(v)`` (m^2/s^2), its `gradient` in the elevation (per
    degree), `variance` ``(g,)`` per height; per ray count tried: `counts`, `elevations`,
    `values` (NaN where infeasible); `n_evaluations` over all counts; `converged` (the best
    count's local search), `feasible`, `message`."""

    elevation: float
    n_rays: int
    value: float
    gradient: float
    variance: np.ndarray
    counts: np.ndarray
    elevations: np.ndarray
    values: np.ndarray
    n_evaluations: int
    feasible: bool
    converged: bool
    message: str = eqx.field(static=True)


def design_vad(
    heights: Float[ArrayLike, " g"],
    *,
    n_rays: Sequence[int] = (4, 6, 8, 12, 16, 24, 36),
    elevation: tuple[float, float] = (5.0, 85.0),
    sigma: float = 0.1,
    range_ref: float = 100.0,
    range_exponent: float = 1.0,
    scan_time: float | None = None,
    move_time: float = 0.0,
    n_coarse: int = 16,
    n_starts: int = 2,
    solver=None,
    max_steps: int = 60,
) -> VadDesign:
    """Elevation and ray count of a full-turn VAD for the smallest `vad_fit` variance of
    ``(u, v)`` at `heights` (m above the lidar; module docs).

    **Arguments:**

    - `n_rays`: the ray counts to try (each >= 3; discrete: enumerated).
    - `elevation`: ``(low, high)`` degree bounds of the continuous elevation.
    - `sigma`, `range_ref`, `range_exponent`: LOS noise ``sigma (range / range_ref)^k`` (m/s).
    - `scan_time`, `move_time`: with a scan time (s), each ray accumulates ``scan_time / n -
      move_time`` s and its noise is divided by the square root of that (a count leaving no
      accumulation is infeasible).
    - `n_coarse`, `n_starts`, `solver`, `max_steps`: the search over the elevation.

    **Returns:** a `VadDesign`; one compiled program serves every ray count.
    """
    fname = "design_vad"
    lo_e, hi_e = (float(v) for v in elevation)
    if not (0 < lo_e < hi_e < 90):
        raise ValueError(f"{fname}: `elevation` must be (low, high) degrees in (0, 90) with "
                         f"low < high, got {elevation!r}.")
    _search.check_counts(fname, n_coarse=n_coarse, n_starts=n_starts, max_steps=max_steps)
    pb = _vad_problem(fname, heights, n_rays, sigma, range_ref, range_exponent, scan_time,
                      move_time)
    dt = pb.heights.dtype
    lo, hi = jnp.asarray([lo_e], dt), jnp.asarray([hi_e], dt)
    solver = _search.default_solver(dt) if solver is None else solver
    counts = [int(n) for n in np.atleast_1d(n_rays)]
    results = []
    for n in counts:
        q = eqx.tree_at(lambda r: r.n_rays, pb, jnp.asarray(float(n), dt))
        results.append(_search.search(_vad_objective, q, lo, hi, n_coarse=n_coarse,
                                      n_starts=n_starts, solver=solver, max_steps=max_steps))
    values = np.array([r["value"] if r["feasible"] else np.nan for r in results])
    elevations = np.array([r["x"][0] if r["feasible"] else np.nan for r in results])
    n_eval = sum(int(r["n_evaluations"]) for r in results)
    if not np.any(np.isfinite(values)):
        return VadDesign(np.nan, 0, np.nan, np.nan, np.full(pb.heights.shape, np.nan),
                         np.asarray(counts), elevations, values, n_eval, False, False,
                         "no ray count is feasible (no accumulation time left); no optimum")
    k = int(np.nanargmin(values))
    r = results[k]
    return VadDesign(float(r["x"][0]), counts[k], float(r["value"]), float(r["gradient"][0]),
                     np.asarray(r["aux"]), np.asarray(counts), elevations, values, n_eval, True,
                     bool(r["converged"]), _search.message(bool(r["converged"])))
