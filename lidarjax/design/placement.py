"""Where to put a profiling lidar: the location (and optionally the cone angle and a heading
offset) that makes the flow distortion, or its uncertainty, smallest over all inflow
directions, found by optimisation through `lidarjax.simulate`.

**Decision variables** (physical units): the location in a `RegionBox` (each coordinate whose
bounds differ is free) or in a `RegionPolygon` (``x``, ``y`` free, ``z`` the surface plus a
height), then the cone angle (degrees, `cone_angle` bounds) and a heading offset (degrees
added to the mount's ``gamma``, `heading` bounds) when asked for. Heights stay fixed.

**Inflow directions** ``k = 1..s`` (each weighted by a wind rose ``w_k``, uniform by default):

- runs of one site (a list or stack of fields, one free stream ``u_ref`` each): the location
  is the same in every run;
- a scene with its own ``direction`` (`lidarjax.scenes.hemisphere`, ...) and `directions`:
  one copy of the scene per direction, its free stream ``speed * heading(direction)``;
- one CFD run seen by a rotated platform (`rotations`, degrees, about the vertical through
  `pivot`): run ``k`` sees the lidar at ``pivot + R(rotation_k) (location - pivot)`` with
  ``beta + rotation_k`` (the frame chain of `lidarjax.frames`), the seed's convention.

**Objectives** per direction ``k`` and height ``j``, with ``e_U = C_U - 1`` and ``e_th`` the
direction correction (`Simulation.cff_U`, `cff_th`, degrees) and
``e^2 = e_U^2 + (direction_weight e_th)^2`` (`direction_weight` per degree, 0.01 by default:
one degree counts as 1 % of speed):

- ``"rms"``: ``sqrt(sum_k w_k mean_j e^2)``;
- ``"worst"``: the largest ``e`` over directions (with ``w_k > 0``) and heights is not smooth;
  it is replaced by a smooth surrogate, ``smoothing="pnorm"``:
  ``(sum_k w_k mean_j e^p)^(1/p)`` (`p`, 8 by default; it tends to the maximum as ``p`` grows,
  from below), or ``smoothing="lse"``: ``tau log(sum_k w_k mean_j exp(e / tau))``
  (`temperature` ``tau``, 0.005 by default; within ``tau log(s h)`` below the maximum). The
  exact worst is reported beside it (`Placement.worst`);
- ``"uncertainty"``: the installation-uncertainty budget of the corrected speed: per direction
  and height the standard uncertainty ``u(C_U) = sqrt(J C J^T)`` of the speed correction from
  the installation's standard uncertainties `std` (`lidarjax.uncertainty`'s inputs, e.g.
  ``{"epsilon": 0.5, "pitch": 0.2, "roll": 0.2}``), combined as ``sqrt(sum_k w_k mean_j u^2)``;
- a callable ``objective(sim)`` of the batched `lidarjax.Simulation` (leading axis ``s``,
  then heights): a scalar, or one value per direction (then ``sum_k w_k value_k``).

Infeasible locations: in a solid or off the grid (`simulate` gives NaN and flags there), closer
than `min_clearance` to a solid (the field is sampled at the location and at 26 points of the
sphere of that radius around it), outside the polygon, or with a non-finite objective.

**Search**: a coarse grid of about `n_coarse` locations (at the initial cone angle and
heading), then a projected BFGS in the region's bounding box (`_search.BoxBFGS`: it stops
exactly on a bound where the optimum lies there), or the optimistix `solver` given, from the
`n_starts` best feasible ones, all starts in one compiled program (`jax.vmap`); every number
(location, angles, weights) is a dynamic input, so new candidates never recompile.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._precision import safe_sqrt
from .._util import map_in_batches
from ..angles import heading as heading_vector
from ..angles import wind_direction
from ..batch import rotation_arguments, stack_fields, unstack_field
from ..corrections import DEFAULT_RATIO_TOL
from ..field import AbstractField, GridField
from ..forward import Simulation, _simulate
from ..frames import cfd_to_north_rotation, rotate, rotation_z
from ..mount import Mount
from ..probe import AbstractProbe
from ..progress import progress_meter
from ..roses import CorrectionRose
from ..scan import Scan
from ..sensitivity import _covariance, _expand, _jacobian_one, _map_sectors
from . import _search

__all__ = ["RegionBox", "RegionPolygon", "Placement", "design_placement", "placement_problem",
           "placement_objective", "evaluate_placements", "OBJECTIVES"]

OBJECTIVES = ("worst", "rms", "uncertainty")
_SMOOTHING = ("pnorm", "lse")


@dataclasses.dataclass(frozen=True)
class RegionBox:
    """A box of candidate locations, CFD metres: `lo` and `hi` ``(3,)``; a coordinate whose
    bounds are equal is fixed (``lo = hi``), the others are decision variables."""

    lo: tuple[float, float, float]
    hi: tuple[float, float, float]

    def __post_init__(self):
        lo = np.asarray(self.lo, np.float64)
        hi = np.asarray(self.hi, np.float64)
        if lo.shape != (3,) or hi.shape != (3,):
            raise ValueError(f"RegionBox: `lo` and `hi` must be (x, y, z) in CFD metres, got "
                             f"{self.lo!r} and {self.hi!r}.")
        if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi))):
            raise ValueError(f"RegionBox: bounds must be finite, got {self.lo!r}, {self.hi!r}.")
        if np.any(hi < lo):
            raise ValueError(f"RegionBox: empty region, `hi` {hi.tolist()} below `lo` "
                             f"{lo.tolist()} in {['xyz'[i] for i in np.nonzero(hi < lo)[0]]}; "
                             f"give lo <= hi.")
        if np.all(hi == lo):
            raise ValueError("RegionBox: the box is a single point (lo = hi); give a range in "
                             "at least one coordinate.")
        object.__setattr__(self, "lo", tuple(lo.tolist()))
        object.__setattr__(self, "hi", tuple(hi.tolist()))

    @property
    def free(self) -> tuple[int, ...]:
        return tuple(i for i in range(3) if self.hi[i] > self.lo[i])

    def bounds(self):
        f = self.free
        return np.asarray(self.lo)[list(f)], np.asarray(self.hi)[list(f)]

    @property
    def names(self) -> tuple[str, ...]:
        return tuple("xyz"[i] for i in self.free)


@dataclasses.dataclass(frozen=True)
class RegionPolygon:
    """A polygon of candidate locations in the horizontal plane (its edges included), `height`
    (m) above the surface.

    - `vertices`: ``(n, 2)`` CFD ``(x, y)`` metres, ``n >= 3``, in order (either sense).
    - `height`: metres above the surface (the lidar's beam origin).
    - `surface`: None: from the field (a `GridField`: the top of the solid nodes of each
      column, bilinear between columns; a scene: the plane ``z = 0``); a number: a plane at
      that ``z``; or a function ``surface(x, y) -> z`` of JAX arrays (differentiable, e.g.
      ``sqrt(max(R^2 - x^2 - y^2, 0))`` for a hemisphere).
    """

    vertices: tuple
    height: float
    surface: float | Callable | None = None

    def __post_init__(self):
        v = np.asarray(self.vertices, np.float64)
        if v.ndim != 2 or v.shape[1] != 2 or v.shape[0] < 3:
            raise ValueError(f"RegionPolygon: `vertices` must be (n, 2) with n >= 3 (x, y) CFD "
                             f"metres, got shape {v.shape}.")
        if not np.all(np.isfinite(v)):
            raise ValueError("RegionPolygon: vertices must be finite.")
        area = 0.5 * abs(np.sum(v[:, 0] * np.roll(v[:, 1], -1) - np.roll(v[:, 0], -1) * v[:, 1]))
        if not area > 0:
            raise ValueError("RegionPolygon: the polygon has zero area (an empty region); give "
                             "at least three vertices not on one line.")
        if not (np.isfinite(self.height) and self.height >= 0):
            raise ValueError(f"RegionPolygon: `height` must be >= 0 m above the surface, got "
                             f"{self.height!r}.")
        object.__setattr__(self, "vertices", tuple(map(tuple, v.tolist())))

    free = (0, 1)
    names = ("x", "y")

    def bounds(self):
        v = np.asarray(self.vertices)
        return v.min(axis=0), v.max(axis=0)


class _Problem(eqx.Module):
    """Everything the compiled objective needs (arrays dynamic, configuration static)."""

    field: AbstractField
    scan: Scan
    mount: Mount  # batched over directions; its location is replaced
    heights: Array
    u_refs: Array
    rotations: Array  # (s,) degrees
    pivot: Array  # (3,)
    weights: Array  # (s,)
    base: Array  # (3,) the fixed coordinates
    vertices: Array | None
    surface_axes: tuple | None
    surface_table: Array | None
    height: Array
    offsets: Array  # (m, 3) clearance sample points relative to the location
    p: Array
    temperature: Array
    direction_weight: Array
    chol: Array | None
    probe: AbstractProbe
    axes: tuple = eqx.field(static=True)
    kind: str = eqx.field(static=True)  # "box" or "polygon"
    surface_kind: str = eqx.field(static=True)  # "plane", "grid", "callable"
    surface_fn: Callable | None = eqx.field(static=True)
    free: tuple = eqx.field(static=True)
    has_cone: bool = eqx.field(static=True)
    has_heading: bool = eqx.field(static=True)
    objective: str | Callable = eqx.field(static=True)
    target: str = eqx.field(static=True)  # "free" (cff_*) or "point" (cfp_*)
    smoothing: str = eqx.field(static=True)
    names: tuple = eqx.field(static=True)
    ratio_tol: float = eqx.field(static=True)


def _bilinear(xs, ys, table, x, y):
    """Bilinear in the surface table; on a node line, the cell above it (as the field's
    trilinear sampling: one side's derivative for both)."""

    def locate(axis, v):
        i = jnp.clip(jnp.searchsorted(axis, v, side="right") - 1, 0, axis.shape[0] - 2)
        t = (v - axis[i]) / (axis[i + 1] - axis[i])
        return i, jnp.clip(t, 0.0, 1.0)

    i, tx = locate(xs, x)
    j, ty = locate(ys, y)
    z00, z10 = table[i, j], table[i + 1, j]
    z01, z11 = table[i, j + 1], table[i + 1, j + 1]
    return (1 - tx) * ((1 - ty) * z00 + ty * z01) + tx * ((1 - ty) * z10 + ty * z11)


def _inside_polygon(v, x, y):
    """Inside by the even-odd rule, or on an edge (the polygon is closed: an optimum on
    its boundary is feasible)."""
    x0, y0 = v[:, 0], v[:, 1]
    x1, y1 = jnp.roll(x0, -1), jnp.roll(y0, -1)
    crosses = (y0 > y) != (y1 > y)
    xc = x0 + (y - y0) * (x1 - x0) / jnp.where(y1 != y0, y1 - y0, 1.0)
    inside = jnp.sum(crosses & (x < xc)) % 2 == 1
    ex, ey, px, py = x1 - x0, y1 - y0, x - x0, y - y0
    along = ex * px + ey * py
    length2 = ex**2 + ey**2
    cross = ex * py - ey * px
    eps = 8 * jnp.finfo(jnp.result_type(x)).eps
    on_edge = (jnp.abs(cross) <= eps * length2 + eps * jnp.abs(along)) & (along >= 0) & (
        along <= length2)
    return inside | jnp.any(on_edge)


def box_location(base, free, x):
    """The point of a `RegionBox`: `base` ``(3,)`` with coordinates `free` set from `x`."""
    loc = jnp.asarray(base, x.dtype)
    for k, i in enumerate(free):
        loc = loc.at[i].set(x[k])
    return loc


def _location(pb: _Problem, x):
    if pb.kind == "box":
        return box_location(pb.base, pb.free, x), jnp.asarray(True)
    px, py = x[0], x[1]
    if pb.surface_kind == "grid":
        zs = _bilinear(pb.surface_axes[0], pb.surface_axes[1], pb.surface_table, px, py)
    elif pb.surface_kind == "callable":
        zs = jnp.asarray(pb.surface_fn(px, py), x.dtype)
    else:
        zs = pb.base[2]
    return jnp.stack([px, py, zs + pb.height]), _inside_polygon(pb.vertices, px, py)


def _configure(pb: _Problem, x):
    """The batched mount, scan and the location for decision vector `x`."""
    loc, inside = _location(pb, x)
    k = len(pb.free)
    scan = pb.scan
    if pb.has_cone:
        scan = eqx.tree_at(lambda s: s.cone_angle, scan, x[k].astype(scan.cone_angle.dtype))
        k += 1
    mount = pb.mount
    if pb.has_heading:
        mount = eqx.tree_at(lambda m: m.gamma, mount, mount.gamma + x[k])
    rot = jax.vmap(rotation_z)(pb.rotations)  # (s, 3, 3)
    locs = pb.pivot + jnp.einsum("sij,j->si", rot, loc - pb.pivot)
    mount = eqx.tree_at(lambda m: (m.location, m.location_lo), mount,
                        (locs.astype(mount.location.dtype), jnp.zeros_like(mount.location)))
    return scan, mount, loc, inside


def _first_field(field, axes):
    if axes[0] is None:
        return field
    return unstack_field(field, field.velocity[0]) if isinstance(field, GridField) else \
        jax.tree_util.tree_map(lambda a: a[0], field)


def _clearance_ok(pb: _Problem, loc):
    f = _first_field(pb.field, pb.axes)
    local = loc - (f.origin + f.origin_lo)
    v = f.sample_local(local + pb.offsets)
    return jnp.all(jnp.isfinite(v))


def _simulations(pb: _Problem, scan, mount) -> Simulation:
    def one(f, m, u):
        return _simulate(f, scan, m, pb.heights, u, pb.probe, pb.ratio_tol,
                         point_reference=pb.target == "point")

    return _map_sectors(one, pb.field, mount, pb.u_refs, pb.axes)


def _aggregate(pb: _Problem, e2, ok):
    """Weighted aggregate of squared errors ``(s, h)``."""
    w = pb.weights[:, None] / e2.shape[1]
    e2 = jnp.where(ok, e2, 0.0)
    if pb.objective in ("rms", "uncertainty"):
        return safe_sqrt(jnp.sum(w * e2))
    if pb.smoothing == "pnorm":
        s = jnp.sum(w * jnp.where(e2 > 0, e2, 1.0) ** (pb.p / 2) * (e2 > 0))
        return jnp.where(s > 0, jnp.where(s > 0, s, 1.0) ** (1.0 / pb.p), 0.0)
    e = safe_sqrt(e2)
    return pb.temperature * jax.scipy.special.logsumexp(e / pb.temperature, b=w)


def _objective(pb: _Problem, x):
    """``(value, feasible, (C_U, C_th, free-stream direction, location))`` at the physical
    decision vector `x` (module docs)."""
    scan, mount, loc, inside = _configure(pb, x)
    feasible = inside & _clearance_ok(pb, loc)
    used = pb.weights > 0
    if pb.objective == "uncertainty":
        cu, cth = ("cfp_U", "cfp_th") if pb.target == "point" else ("cff_U", "cff_th")
        cfg = (pb.names, (cu, cth), False, pb.target == "point", pb.ratio_tol)

        def one(f, m, u):
            value, jac = _jacobian_one(f, scan, m, pb.heights, u, pb.probe, cfg)
            return value[cu], value[cth], jac[cu]

        c_u, c_th, jac = _map_sectors(one, pb.field, mount, pb.u_refs, pb.axes)
        ok = jnp.isfinite(c_u) & jnp.all(jnp.isfinite(jac), axis=-1)
        jac = jnp.where(ok[..., None], jac, 0.0)
        e2 = jnp.sum(jnp.einsum("shp,qp->shq", jac, pb.chol) ** 2, axis=-1)  # J C J^T
        free_dir = _free_directions(pb, mount)
    else:
        sims = _simulations(pb, scan, mount)
        c_u, c_th = (sims.cfp_U, sims.cfp_th) if pb.target == "point" else (sims.cff_U,
                                                                            sims.cff_th)
        free_dir = wind_direction(sims.free_velocity)
        if callable(pb.objective):
            value = jnp.asarray(pb.objective(sims))
            if value.ndim == 1:
                value = jnp.sum(pb.weights * jnp.where(used, value, 0.0))
            good = jnp.all(jnp.isfinite(sims.lidar_velocity) | ~used[:, None, None])
            return value, feasible & good & jnp.isfinite(value), (c_u, c_th, free_dir, loc)
        ok = jnp.isfinite(c_u) & jnp.isfinite(c_th)
        e_u = jnp.where(ok, c_u - 1.0, 0.0)
        e_th = jnp.where(ok, c_th, 0.0) * pb.direction_weight
        e2 = e_u**2 + e_th**2
    good = jnp.all(ok | ~used[:, None])
    value = _aggregate(pb, e2, ok)
    return value, feasible & good & jnp.isfinite(value), (c_u, c_th, free_dir, loc)


def _free_directions(pb: _Problem, mount):
    """Meteorological free-stream direction in each sector's north frame, degrees."""
    return jax.vmap(lambda m, u: wind_direction(rotate(cfd_to_north_rotation(m), u)))(
        mount, pb.u_refs)


class Placement(eqx.Module):
    """The result of `design_placement` (``d`` decision variables, ``s`` directions, ``h``
    heights, ``n`` starts).

    - `names`: ``(d,)`` the decision variables (``x``, ``y``, ``z``, ``cone_angle``,
      ``heading``); `x`: their optimum (m, degrees); `location`: ``(3,)`` CFD metres there
      (NaN when nothing feasible was found).
    - `value`: the objective there; `gradient`: ``(d,)`` its gradient (per m, per degree).
    - `worst`, `rms`: the exact largest and RMS error ``e`` (module docs) over directions and
      heights at the optimum (NaN for a user objective or ``"uncertainty"``).
    - `start`: ``(d,)`` the start of the winning local search and `start_value`;
      `path`: ``(k, d)`` its accepted iterates (first the start), `path_values` ``(k,)``.
    - `rose_start`, `rose`: `lidarjax.CorrectionRose` (``reference="free"``) of ``C_U`` and
      ``C_th`` against the free-stream direction at the start and at the optimum.
    - `n_evaluations`: objective evaluations (the coarse stage's and every local step's; each
      simulates all ``s`` directions); `n_forward`: ``s`` times that, the `simulate` calls a
      grid search is compared by; `n_coarse`: the coarse stage's candidates.
    - `feasible`, `converged`: False with `message` saying why (e.g. every candidate in a
      solid); then `x` and `location` are NaN, never reported as an optimum.
    - `coarse`, `coarse_values`: the coarse stage's candidates ``(m, d)`` and objective
      (NaN where infeasible): a map of the objective over the region.
    """

    names: tuple = eqx.field(static=True)
    x: np.ndarray
    location: np.ndarray
    value: float
    gradient: np.ndarray
    worst: float
    rms: float
    start: np.ndarray
    start_value: float
    path: np.ndarray
    path_values: np.ndarray
    rose_start: CorrectionRose | None
    rose: CorrectionRose | None
    n_evaluations: int
    n_forward: int
    n_coarse: int
    feasible: bool
    converged: bool
    message: str = eqx.field(static=True)
    coarse: np.ndarray
    coarse_values: np.ndarray


def _rose(cff_u, cff_th, directions, target="free") -> CorrectionRose:
    d = np.mod(np.asarray(directions, np.float64), 360.0)
    order = np.argsort(d)
    return CorrectionRose(jnp.asarray(d[order]), jnp.asarray(np.asarray(cff_u)[order]),
                          jnp.asarray(np.asarray(cff_th)[order]), "free", target, False)


def _surface_table(field: GridField):
    """Top of the solid nodes per column of a grid (the lowest z above which every node is
    finite); columns without solids get the grid's bottom, all-solid columns NaN."""
    v = np.asarray(field.velocity)
    finite = np.all(np.isfinite(v), axis=-1)  # (nx, ny, nz)
    z = np.asarray(field.z_local, np.float64) + float(np.asarray(field.origin)[2])
    # suffix: every node from k upwards is finite
    suffix = np.flip(np.logical_and.accumulate(np.flip(finite, -1), axis=-1), -1)
    any_ok = suffix.any(axis=-1)
    first = np.argmax(suffix, axis=-1)
    table = np.where(any_ok, z[first], np.nan)
    x = np.asarray(field.x_local, np.float64) + float(np.asarray(field.origin)[0])
    y = np.asarray(field.y_local, np.float64) + float(np.asarray(field.origin)[1])
    return x, y, table


def _clearance_offsets(radius: float) -> np.ndarray:
    if radius <= 0:
        return np.zeros((1, 3))
    g = np.array([(i, j, k) for i in (-1, 0, 1) for j in (-1, 0, 1) for k in (-1, 0, 1)
                  if (i, j, k) != (0, 0, 0)], np.float64)
    g /= np.linalg.norm(g, axis=1, keepdims=True)
    return np.concatenate([np.zeros((1, 3)), radius * g])


def _field_extent(field):
    if isinstance(field, GridField):
        o = np.asarray(field.origin, np.float64)
        if o.ndim == 2:
            o = o[0]
        axes = (field.x_local, field.y_local, field.z_local)
        return (np.array([float(np.min(a)) for a in axes]) + o,
                np.array([float(np.max(a)) for a in axes]) + o)
    return None


def _degrees(fname, name, value):
    """`value` as finite degrees ``(s,)``, at least one, or one line naming `name`."""
    d = np.asarray(value, np.float64).ravel()
    if d.size == 0 or not np.all(np.isfinite(d)):
        raise ValueError(f"{fname}: `{name}` must be finite degrees, at least one.")
    return d


def _directions_setup(fname, field, mount, u_ref, directions, rotations, pivot):
    """Fields, batched template mount, free streams ``(s, 3)``, rotations ``(s,)``, pivot."""
    if not isinstance(mount, Mount) or mount.batch_shape:
        raise ValueError(f"{fname}: `mount` must be one lidarjax.Mount (the template: angles; "
                         f"its location is the initial guess).")
    if directions is not None and rotations is not None:
        raise ValueError(f"{fname}: give `directions` (a scene's inflow) or `rotations` (one "
                         f"run, rotated platform), not both.")
    single = isinstance(field, AbstractField) and not (
        (isinstance(field, GridField) and field.velocity.ndim == 5) or
        (not isinstance(field, GridField) and np.ndim(field.origin) == 2))
    if not isinstance(field, AbstractField):
        field = stack_fields(list(field))
    if directions is not None:
        if not single or not hasattr(field, "direction"):
            raise ValueError(f"{fname}: `directions` needs one scene with its own `direction` "
                             f"(e.g. lidarjax.scenes.hemisphere); for a CFD run use "
                             f"`rotations` (rotated platform) or one field per direction.")
        d = _degrees(fname, "directions", directions)
        dt = field.dtype
        stacked = jax.tree_util.tree_map(lambda a: jnp.broadcast_to(a, (d.size,) + a.shape),
                                         field)
        stacked = eqx.tree_at(lambda f: f.direction, stacked, jnp.asarray(d, dt))
        speed = getattr(field, "speed", None)
        if u_ref is None:
            if speed is None:
                raise ValueError(f"{fname}: the scene has no `speed`; give `u_ref`.")
            u_refs = jnp.stack([speed * heading_vector(di, dt) for di in d])
        else:
            u_refs = jnp.broadcast_to(jnp.asarray(u_ref, dt), (d.size, 3))
        rot = np.zeros(d.size)
        field = stacked
    elif rotations is not None:
        if not single:
            raise ValueError(f"{fname}: `rotations` rotate the platform in one run; give one "
                             f"field.")
        rot = _degrees(fname, "rotations", rotations)
        if pivot is None:
            raise ValueError(f"{fname}: `rotations` need the `pivot` (x, y) the platform turns "
                             f"about, CFD metres.")
        if u_ref is None:
            raise ValueError(f"{fname}: `rotations` need the run's free stream `u_ref`.")
        u_refs = jnp.broadcast_to(jnp.asarray(u_ref, field.dtype), (rot.size, 3))
    else:
        if single:
            n = 1
        elif isinstance(field, GridField):
            n = field.velocity.shape[0]
        else:
            n = np.shape(field.origin)[0]
        if u_ref is None:
            if not (hasattr(field, "speed") and hasattr(field, "direction")):
                raise ValueError(f"{fname}: give `u_ref`, the free stream of each run (s, 3) "
                                 f"CFD m/s.")
            one = lambda f: f.speed * heading_vector(f.direction, f.dtype)  # noqa: E731
            u_refs = one(field)[None] if single else jax.vmap(one)(field)
        else:
            u_refs = jnp.asarray(u_ref, field.dtype)
            u_refs = jnp.broadcast_to(u_refs, (n, 3)) if u_refs.ndim == 1 else u_refs
        rot = np.zeros(u_refs.shape[0])
    s = rot.size
    piv = np.zeros(3) if pivot is None else np.asarray(pivot, np.float64).ravel()
    if piv.size == 2:
        piv = np.append(piv, 0.0)
    if piv.size != 3 or not np.all(np.isfinite(piv)):
        raise ValueError(f"{fname}: `pivot` must be (x, y) or (x, y, z) finite CFD metres.")
    batched = Mount(np.broadcast_to(np.asarray(mount.location, np.float64), (s, 3)),
                    beta=np.asarray(mount.beta, np.float64) + rot, gamma=mount.gamma,
                    psi=mount.psi, epsilon=mount.epsilon, pitch=mount.pitch, roll=mount.roll)
    return field, batched, u_refs, rot, piv


def _bounds_arg(fname, name, value):
    if value is None:
        return None
    b = np.asarray(value, np.float64).ravel()
    if b.shape != (2,) or not np.all(np.isfinite(b)) or not b[1] > b[0]:
        raise ValueError(f"{fname}: `{name}` must be (low, high) degrees with low < high, got "
                         f"{value!r}.")
    return b


def _check_options(fname, region, scan, objective, target, smoothing, p, temperature,
                   direction_weight, min_clearance):
    """One-line errors for the region's type and the objective's options."""
    if not isinstance(region, RegionBox | RegionPolygon):
        raise ValueError(f"{fname}: `region` must be a lidarjax.RegionBox or RegionPolygon, got "
                         f"{type(region).__name__}.")
    if not (isinstance(objective, str) and objective in OBJECTIVES) and not callable(objective):
        raise ValueError(f"{fname}: `objective` must be one of {OBJECTIVES} or a function of "
                         f"the Simulation, got {objective!r}.")
    if target not in ("free", "point"):
        raise ValueError(f"{fname}: `target` must be 'free' (C_U, C_th to the free stream) or "
                         f"'point' (to the wind above the lidar), got {target!r}.")
    if smoothing not in _SMOOTHING:
        raise ValueError(f"{fname}: `smoothing` must be one of {_SMOOTHING}, got {smoothing!r}.")
    for name, val, low in (("p", p, 1.0), ("temperature", temperature, 0.0),
                           ("direction_weight", direction_weight, -1e-300)):
        if not (np.isfinite(val) and val > low):
            raise ValueError(f"{fname}: `{name}` must be finite and > {max(low, 0):g}, got "
                             f"{val!r}.")
    if not (np.isfinite(min_clearance) and min_clearance >= 0):
        raise ValueError(f"{fname}: `min_clearance` must be >= 0 m, got {min_clearance!r}.")
    if not isinstance(scan, Scan):
        raise ValueError(f"{fname}: `scan` must be a profiling lidarjax.Scan (windcube_v1, ...).")


def _rose_weights(fname, weights, s):
    """The wind rose's weights ``(s,)``, normalised."""
    w = np.ones(s) if weights is None else np.asarray(weights, np.float64).ravel()
    if w.shape != (s,) or not np.all(np.isfinite(w)) or np.any(w < 0) or not w.sum() > 0:
        raise ValueError(f"{fname}: `weights` (the wind rose) must be {s} finite values >= 0, "
                         f"not all 0; got shape {w.shape}.")
    return w / w.sum()


def _check_region_on_grid(fname, region, field):
    """A region that lies off a `GridField` in some coordinate: one line naming it."""
    extent = _field_extent(field)
    if extent is None:
        return
    rlo, rhi = np.zeros(3), np.zeros(3)
    if isinstance(region, RegionBox):
        rlo, rhi = np.asarray(region.lo), np.asarray(region.hi)
        dims = range(3)
    else:
        rlo[:2], rhi[:2] = region.bounds()
        dims = range(2)
    out = [("xyz"[i], rlo[i], rhi[i]) for i in dims
           if rhi[i] < extent[0][i] or rlo[i] > extent[1][i]]
    if out:
        a, r0, r1 = out[0]
        raise ValueError(f"{fname}: the region lies outside the grid in {a} ([{r0:g}, "
                         f"{r1:g}] m; the grid spans [{extent[0]['xyz'.index(a)]:g}, "
                         f"{extent[1]['xyz'.index(a)]:g}] m); move the region onto the "
                         f"grid.")


def _decision_variables(region, mount, scan, cone_b, head_b):
    """Names, bounds ``lo``, ``hi`` and the initial guess of the decision variables: the
    region's free coordinates, then the cone angle and the heading offset if asked for."""
    lo, hi = (list(b) for b in region.bounds())
    names = list(region.names)
    x_init = list(np.asarray(mount.location, np.float64)[list(region.free)])
    for name, b, init in (("cone_angle", cone_b, lambda: float(scan.cone_angle)),
                          ("heading", head_b, lambda: 0.0)):
        if b is not None:
            names.append(name)
            lo.append(b[0])
            hi.append(b[1])
            x_init.append(float(np.clip(init(), b[0], b[1])))
    return names, lo, hi, np.clip(np.asarray(x_init), lo, hi)


def _region_surface(fname, region, field, axes, dtype):
    """How the location follows from the decision variables: ``(kind, base, vertices,
    surface_kind, surface_fn, surface_axes, surface_table)`` (`_Problem`)."""
    base = np.zeros(3)
    if isinstance(region, RegionBox):
        return "box", np.asarray(region.lo), None, "plane", None, None, None
    vertices = jnp.asarray(np.asarray(region.vertices), dtype)
    surf = region.surface
    if callable(surf):
        return "polygon", base, vertices, "callable", surf, None, None
    if surf is None and isinstance(field, GridField):
        sx, sy, table = _surface_table(_first_field(field, axes))
        if not np.any(np.isfinite(table)):
            raise ValueError(f"{fname}: the grid is solid everywhere; no surface to stand on.")
        table = np.where(np.isfinite(table), table, np.nanmax(table) + 1e6)
        return ("polygon", base, vertices, "grid", None,
                (jnp.asarray(sx, dtype), jnp.asarray(sy, dtype)), jnp.asarray(table, dtype))
    # a plane at the given z, or for a scene the plane z = 0 of the CFD frame
    base[2] = 0.0 if surf is None else float(surf)
    return "polygon", base, vertices, "plane", None, None, None


def _installation_covariance(fname, objective, std, dtype):
    """For ``objective="uncertainty"``: the installation inputs' names and the symmetric
    square root of their covariance (from `std`); else ``((), None)``."""
    if objective != "uncertainty":
        return (), None
    if not isinstance(std, Mapping) or not std:
        raise ValueError(f"{fname}: objective='uncertainty' needs `std`, the installation's "
                         f"standard uncertainties, e.g. {{'epsilon': 0.5, 'pitch': 0.2}}.")
    in_names = _expand(list(std), fname)
    bad = [n for n in in_names if n in ("speed", "direction") or n.startswith("scene.")]
    if bad:
        raise ValueError(f"{fname}: `std` names installation inputs only, not {bad}.")
    std_in, corr = _covariance(in_names, std, None, fname)
    cov = np.outer(std_in, std_in) * corr
    wv, vv = np.linalg.eigh(cov)
    return in_names, jnp.asarray((vv * np.sqrt(np.clip(wv, 0, None))) @ vv.T, dtype)


def placement_problem(field, scan, mount, heights, region, *, u_ref=None, directions=None,
                      rotations=None, pivot=None, weights=None, objective="worst", target="free",
                      smoothing="pnorm", p=8.0, temperature=0.005, direction_weight=0.01,
                      std=None, min_clearance=0.0, cone_angle=None, heading=None, probe=None,
                      ratio_tol=DEFAULT_RATIO_TOL, fname="design_placement"):
    """Validate and assemble the compiled problem (`design_placement`'s arguments). Returns
    ``(problem, lo, hi, x_init, names)``: the objective is ``placement_objective(problem,
    x)``, `lo`, `hi` the decision variables' bounds and `names` their names."""
    _check_options(fname, region, scan, objective, target, smoothing, p, temperature,
                   direction_weight, min_clearance)
    field, batched, u_refs, rot, piv = _directions_setup(fname, field, mount, u_ref, directions,
                                                         rotations, pivot)
    w = _rose_weights(fname, weights, rot.size)
    field, batched, u_refs, heights, probe, axes, _ = rotation_arguments(
        fname, field, scan, batched, heights, u_refs, probe)
    dtype = field.dtype
    cone_b = _bounds_arg(fname, "cone_angle", cone_angle)
    head_b = _bounds_arg(fname, "heading", heading)
    if cone_b is not None and not (0 < cone_b[0] and cone_b[1] < 90):
        raise ValueError(f"{fname}: `cone_angle` bounds must lie in (0, 90) degrees.")
    _check_region_on_grid(fname, region, field)
    names, lo, hi, x_init = _decision_variables(region, mount, scan, cone_b, head_b)
    kind, base, vertices, surface_kind, surface_fn, s_axes, s_table = _region_surface(
        fname, region, field, axes, dtype)
    in_names, chol = _installation_covariance(fname, objective, std, dtype)
    problem = _Problem(
        field=field, scan=scan, mount=batched, heights=heights, u_refs=jnp.asarray(u_refs, dtype),
        rotations=jnp.asarray(rot, dtype), pivot=jnp.asarray(piv, dtype),
        weights=jnp.asarray(w, dtype), base=jnp.asarray(base, dtype), vertices=vertices,
        surface_axes=s_axes, surface_table=s_table,
        height=jnp.asarray(getattr(region, "height", 0.0), dtype),
        offsets=jnp.asarray(_clearance_offsets(float(min_clearance)), dtype),
        p=jnp.asarray(p, dtype), temperature=jnp.asarray(temperature, dtype),
        direction_weight=jnp.asarray(direction_weight, dtype), chol=chol, probe=probe,
        axes=axes, kind=kind, surface_kind=surface_kind, surface_fn=surface_fn,
        free=tuple(region.free), has_cone=cone_b is not None, has_heading=head_b is not None,
        objective=objective, target=target, smoothing=smoothing, names=in_names,
        ratio_tol=float(ratio_tol))
    return problem, jnp.asarray(lo, dtype), jnp.asarray(hi, dtype), x_init, tuple(names)


def placement_objective(problem, x: Float[ArrayLike, " d"]):
    """``(value, feasible)`` of the placement objective at decision vector `x` (physical
    units), compiled once per problem structure; `problem` from `placement_problem`."""
    value, ok, _ = _objective_jit(problem, jnp.asarray(x, problem.heights.dtype))
    return value, ok


_objective_jit = eqx.filter_jit(_objective)


def evaluate_placements(problem, xs: Float[ArrayLike, "m d"], *, batch_size: int = 256):
    """``(values, feasible)`` ``(m,)`` of the placement objective at every row of `xs` (a grid
    search, a map of the objective over the region): one compiled program, `batch_size`
    candidates at a time; infeasible candidates get NaN."""
    xs = jnp.atleast_2d(jnp.asarray(xs, problem.heights.dtype))
    values, ok = _many_jit(problem, xs, int(min(batch_size, xs.shape[0])))
    ok = np.asarray(ok) & np.isfinite(np.asarray(values))
    return np.where(ok, np.asarray(values, np.float64), np.nan), ok


@eqx.filter_jit
def _many_jit(problem, xs, batch_size):
    return map_in_batches(lambda x: _objective(problem, x)[:2], xs, batch_size)


def _errors(pb, cff_u, cff_th):
    e2 = (np.asarray(cff_u) - 1.0) ** 2 + (float(pb.direction_weight) * np.asarray(cff_th)) ** 2
    used = np.asarray(pb.weights) > 0
    e2 = e2[used]
    w = np.asarray(pb.weights)[used][:, None] / e2.shape[1]
    return float(np.sqrt(e2.max())), float(np.sqrt(np.sum(w * e2)))


def design_placement(
    field: AbstractField | Sequence[AbstractField],
    scan: Scan,
    mount: Mount,
    heights: Float[ArrayLike, " h"],
    region: RegionBox | RegionPolygon,
    *,
    u_ref: Float[ArrayLike, "*s 3"] | None = None,
    directions: Float[ArrayLike, " s"] | None = None,
    rotations: Float[ArrayLike, " s"] | None = None,
    pivot: Float[ArrayLike, " 2"] | None = None,
    weights: Float[ArrayLike, " s"] | None = None,
    objective: str | Callable[[Simulation], Array] = "worst",
    target: str = "free",
    smoothing: str = "pnorm",
    p: float = 8.0,
    temperature: float = 0.005,
    direction_weight: float = 0.01,
    std: Mapping[str, float] | None = None,
    min_clearance: float = 0.0,
    cone_angle: tuple[float, float] | None = None,
    heading: tuple[float, float] | None = None,
    probe: AbstractProbe | None = None,
    n_coarse: int = 64,
    n_starts: int = 4,
    solver=None,
    max_steps: int = 60,
    batch_size: int = 64,
    fast_compile: bool = True,
    progress=None,
    ratio_tol: float = DEFAULT_RATIO_TOL,
) -> Placement:
    """Optimise a profiling lidar's placement (module docs).

    **Arguments:**

    - `field`, `u_ref`, `directions`, `rotations`, `pivot`: the inflow directions (module
      docs): runs of one site with ``u_ref`` ``(s, 3)`` (CFD m/s); a scene and `directions`
      (meteorological degrees); or one run, its ``u_ref`` and the platform `rotations`
      (degrees) about `pivot` ``(x, y)`` CFD metres.
    - `scan`, `heights`, `probe`: as in `lidarjax.simulate` (heights fixed, m above the lidar).
    - `mount`: the template `lidarjax.Mount`: its angles are kept, its location is the
      initial guess (added to the coarse stage).
    - `region`: a `RegionBox` or `RegionPolygon` (CFD metres).
    - `weights`: ``(s,)`` the wind rose (frequency of each direction; normalised), uniform by
      default.
    - `objective`: ``"worst"``, ``"rms"``, ``"uncertainty"`` (with `std`) or a callable of the
      batched `Simulation`; `smoothing` (``"pnorm"``/``"lse"``), `p`, `temperature`:
      the worst case's smooth surrogate; `direction_weight`: weight of a degree of direction
      error against a unit speed ratio error (1/deg).
    - `target`: ``"free"`` (default: ``C_U``, ``C_th`` to the free stream, `Simulation.cff_U`)
      or ``"point"`` (to the true wind straight above the lidar, `Simulation.cfp_U`: the
      distortion alone, where the free stream also carries an inflow profile's shear).
    - `std`: ``{input: standard uncertainty}`` for ``"uncertainty"`` (`lidarjax.uncertainty`'s
      installation inputs: ``epsilon``, ``pitch``, ``roll``, ``location``, ...).
    - `min_clearance`: metres of fluid required around the lidar.
    - `cone_angle`, `heading`: ``(low, high)`` degree bounds to optimise the cone angle and a
      heading offset (added to ``gamma``) too; None keeps them fixed.
    - `n_coarse`: about how many locations the coarse stage evaluates (a regular grid over
      the decision variables); `n_starts`: local searches from the best of them.
    - `solver`: the local search: default `lidarjax.design._search.BoxBFGS` (projected BFGS
      that stops on a bound, ``rtol=1e-6, atol=1e-9``, looser in float32), or an
      `optimistix.AbstractMinimiser` with ``init/step/terminate`` (in unbounded sigmoid
      variables: it never reaches a bound); `max_steps`: steps (objective evaluations) per
      local search.
    - `batch_size`: coarse candidates evaluated at once.
    - `fast_compile`: on a CPU, compile the search's one program with XLA's quick code
      generation (about 3x faster to compile, slower to run; the search runs in a fraction of
      a second, its compilation takes tens: `lidarjax.design._search.FAST_CPU_OPTIONS`).
    - `progress`: a progress meter (`lidarjax.progress_meter`).

    **Returns:** a `Placement`. Raises `ValueError` before compiling for an empty region, a
    region off the grid, unknown objectives or bad bounds; a region where nothing is feasible
    gives a `Placement` with ``feasible=False`` and a message (no optimum reported).
    """
    fname = "design_placement"
    _search.check_counts(fname, n_coarse=n_coarse, n_starts=n_starts, max_steps=max_steps,
                         batch_size=batch_size)
    problem, lo, hi, x_init, names = placement_problem(
        field, scan, mount, heights, region, u_ref=u_ref, directions=directions,
        rotations=rotations, pivot=pivot, weights=weights, objective=objective, target=target,
        smoothing=smoothing, p=p, temperature=temperature, direction_weight=direction_weight,
        std=std, min_clearance=min_clearance, cone_angle=cone_angle, heading=heading,
        probe=probe, ratio_tol=ratio_tol, fname=fname)
    solver = _search.default_solver(lo.dtype) if solver is None else solver
    meter = progress_meter(progress)
    task = meter.start(1, "design placement (compile and search)", unit="search")
    try:
        res = _search.search(_objective, problem, lo, hi, x_init=x_init, n_coarse=n_coarse,
                             n_starts=n_starts, solver=solver, max_steps=max_steps,
                             batch_size=batch_size, fast_compile=fast_compile)
        meter.update(task, 1)
    finally:
        meter.close(task)
    s = problem.rotations.shape[0]
    n_eval = int(res["n_evaluations"])
    if not res["feasible"]:
        nan = np.full(len(names), np.nan)
        why = ("every candidate of the region is infeasible (in a solid, off the grid, closer "
               "than min_clearance to a solid, outside the polygon, or a non-finite objective)"
               if res["n_feasible"] == 0 else "the local searches ended infeasible")
        return Placement(names, nan, np.full(3, np.nan), np.nan, nan, np.nan, np.nan, nan,
                         np.nan, np.zeros((0, len(names))), np.zeros(0), None, None, n_eval,
                         n_eval * s, int(res["n_coarse"]), False, False, why + "; no optimum",
                         res["coarse"], res["coarse_values"])
    u1, th1, d1, loc = res["aux"]
    u0, th0, d0, _ = res["aux_start"]
    worst = rms = np.nan
    if isinstance(objective, str) and objective != "uncertainty":
        worst, rms = _errors(problem, u1, th1)
    converged = bool(res["converged"])
    msg = _search.message(converged)
    return Placement(names, res["x"], np.asarray(loc, np.float64), res["value"],
                     np.asarray(res["gradient"], np.float64), worst, rms, res["start"],
                     res["start_value"], res["path"], res["path_values"], _rose(u0, th0, d0, target),
                     _rose(u1, th1, d1, target), n_eval, n_eval * s, int(res["n_coarse"]), True,
                     converged, msg, res["coarse"], res["coarse_values"])
