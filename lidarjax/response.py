"""Response tables: what a lidar measures per unit free-stream speed, against inflow direction.

A site is described by CFD runs over inflow directions. With Reynolds independence every
velocity in a run scales with the free-stream speed, so each run gives, per height ``h`` and
beam ``b``, the LOS per unit free-stream speed (the *response*). A `ResponseTable` holds these
numbers for ``s`` tabulated directions and evaluates them at any direction by a periodic cubic
spline (period 360 degrees, continuous second derivative, error ``O(spacing**4)``).

Besides the LOS response a table can hold, all per unit free-stream speed and in the north
frame (``+y`` north, ``+x`` east, ``+z`` up):

- `reconstructed`: ``(s, h, 3)`` the instrument's reconstructed vector (what a ``.sta`` file
  reports), for `lidarjax.invert_reconstructed` and the correction roses;
- `point`: ``(s, h, 3)`` the velocity on the vertical above the lidar (the centre line);
- `beam_velocity`: ``(s, h, b, 3)`` the full velocity at the beam points (ZephyCube's scalar
  correction needs the along-pair and vertical components there, not only the LOS);
- `beam_vectors`: ``(b, 3)`` the beam unit vectors (direction-independent);
- `beam_gradient`: ``(s, h, b, 3, 3)`` the velocity gradient along each beam's probe volume
  (`lidarjax.beam_gradient`), for `lidarjax.calibrate`'s displacement of the measurement
  points by a tilt or turn.

Directions are meteorological: where the wind comes **from**, degrees clockwise from north.

The spline coefficients are computed once on the host (``scipy.interpolate.CubicSpline`` with
``bc_type='periodic'``, any spacing) and stored as arrays; evaluation is pure JAX (locate the
interval, evaluate a cubic), differentiable in the direction and in the tabulated values.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Bool, Float
from scipy.interpolate import CubicSpline

from ._precision import default_float, host_array, is_concrete
from ._util import compiled
from .angles import horizontal_speed, wind_direction
from .forward import Simulation, beam_flow, gradient_along_beams, probe_for_field, simulate
from .frames import cfd_to_north_rotation
from .mount import Mount
from .probe import AbstractProbe, CWProbe, PointProbe, PulsedProbe
from .scan import Scan

__all__ = ["PeriodicSpline", "ResponseTable", "TableRuns", "Instrument", "ProfileTable", "AbstractProfile",
           "PowerLawProfile", "UniformProfile", "profile_from_metadata", "parameter_weights"]


def scan_name(scan: Scan) -> str:
    """The preset a `Scan` follows: ``windcube_v1``, ``windcube_v2``, ``zephir`` (sine fit),
    ``nacelle_2beam``, ``nacelle_4beam``, or ``custom`` (least squares)."""
    return {"sine_fit": "zephir", "least_squares": "custom"}.get(scan.method, scan.method)


def _host_number(x) -> float | None:
    if x is None or not is_concrete(x):
        return None
    v = float(np.asarray(x, np.float64))
    return v if math.isfinite(v) else None


@dataclasses.dataclass(frozen=True)
class Instrument:
    """What a table's CFD runs simulated, so that records from another instrument or
    installation are refused (`lidarjax.check_instrument`): host numbers, degrees and metres.

    - `scan`: the preset (`scan_name`: ``windcube_v2``, ``zephir``, ..., ``custom``);
      `cone_angle_deg`: the scan's cone (half) angle from the vertical; `n_beams`; whether the
      scan has a `vertical_beam`; `tilt_compensation`.
    - `heights_m`: the measurement heights above the lidar.
    - `epsilon_deg`, `pitch_deg`, `roll_deg`: the installation (north offset, tilt) shared by
      every run, or None when the runs' mounts differ or were not given.
    - `probe`: the probe volume (``point``, ``pulsed``, ``cw``) or None.

    Static metadata of a `ResponseTable` (never differentiated); `metadata()` gives the keys
    that `lidarjax.io.save_table` writes and `lidarjax correct` checks.
    """

    scan: str
    cone_angle_deg: float | None
    n_beams: int
    vertical_beam: bool = False
    tilt_compensation: bool = False
    heights_m: tuple[float, ...] | None = None
    epsilon_deg: float | None = None
    pitch_deg: float | None = None
    roll_deg: float | None = None
    probe: str | None = None

    @classmethod
    def of(cls, scan: Scan, mount: Mount | Sequence[Mount] | None = None, heights=None,
           probe: AbstractProbe | None = None) -> Instrument:
        """The instrument of `scan` mounted as `mount` (or a sequence of mounts: their
        shared epsilon, pitch and roll) at `heights` (m), with `probe`."""
        if mount is None:
            mounts = []
        elif isinstance(mount, Mount):
            mounts = list(mount) if mount.batch_shape else [mount]
        else:
            mounts = list(mount)

        def shared(name):
            vals = [_host_number(getattr(m, name)) for m in mounts]
            if not vals or any(v is None for v in vals):
                return None
            return vals[0] if np.allclose(vals, vals[0], atol=1e-9) else None

        hh = None
        if heights is not None and is_concrete(heights):
            hh = tuple(float(v) for v in np.asarray(heights, np.float64).reshape(-1))
        kind = {PointProbe: "point", PulsedProbe: "pulsed", CWProbe: "cw"}.get(type(probe))
        return cls(scan=scan_name(scan), cone_angle_deg=_host_number(scan.cone_angle),
                   n_beams=int(scan.n_beams), vertical_beam=bool(scan.vertical),
                   tilt_compensation=bool(scan.tilt_compensation), heights_m=hh,
                   epsilon_deg=shared("epsilon"), pitch_deg=shared("pitch"),
                   roll_deg=shared("roll"), probe=kind)

    def metadata(self) -> dict[str, Any]:
        """The facts as table-file metadata (None omitted)."""
        out: dict[str, Any] = {"scan": self.scan, "n_beams": self.n_beams,
                               "vertical_beam": self.vertical_beam,
                               "tilt_compensation": self.tilt_compensation}
        for key in ("cone_angle_deg", "epsilon_deg", "pitch_deg", "roll_deg", "probe"):
            if getattr(self, key) is not None:
                out[key] = getattr(self, key)
        if self.heights_m is not None:
            out["heights_m"] = list(self.heights_m)
        return out

    @classmethod
    def from_metadata(cls, meta: Mapping[str, Any]) -> Instrument | None:
        """The instrument a table file's metadata states, or None without ``scan`` and
        ``n_beams``."""
        if not isinstance(meta.get("scan"), str) or not isinstance(meta.get("n_beams"), int):
            return None

        def num(key):
            v = meta.get(key)
            return float(v) if isinstance(v, int | float) and not isinstance(v, bool) else None

        hh = meta.get("heights_m")
        probe = meta.get("probe")
        return cls(scan=meta["scan"], cone_angle_deg=num("cone_angle_deg"),
                   n_beams=meta["n_beams"], vertical_beam=bool(meta.get("vertical_beam", False)),
                   tilt_compensation=bool(meta.get("tilt_compensation", False)),
                   heights_m=tuple(float(v) for v in hh) if isinstance(hh, list) else None,
                   epsilon_deg=num("epsilon_deg"), pitch_deg=num("pitch_deg"),
                   roll_deg=num("roll_deg"),
                   probe=probe if probe in ("point", "pulsed", "cw") else None)

#: Two tabulated directions closer than this (degrees, modulo 360) count as duplicates.
DUPLICATE_TOL = 1e-9


def _host_float(value, name: str) -> np.ndarray:
    if not is_concrete(value):
        raise ValueError(
            f"ResponseTable: `{name}` must be concrete (build tables outside jit); got a tracer."
        )
    return np.asarray(value, dtype=np.float64)


def _spline_coefficients(knots: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Periodic cubic spline coefficients ``(4, s, ...)`` in the normalised interval
    coordinate ``t = (x - knot_k) / width_k``: ``value = c0 + c1 t + c2 t^2 + c3 t^3``."""
    x = np.append(knots, knots[0] + 360.0)
    y = np.concatenate([values, values[:1]], axis=0)
    c = CubicSpline(x, y, axis=0, bc_type="periodic").c  # (4, s, ...), c[m] * (x - x_k)**(3-m)
    w = np.diff(x).reshape((-1,) + (1,) * (values.ndim - 1))
    return np.stack([c[3], c[2] * w, c[1] * w**2, c[0] * w**3])


def locate(start, offsets, widths, uniform: bool, direction):
    """Interval index ``k`` and normalised position ``t`` in ``[0, 1)`` of `direction`
    (degrees, any real) among periodic knots ``start + offsets`` with `widths`."""
    s = offsets.shape[0]
    x = jnp.mod(direction - start, 360.0)
    x = jnp.where(x >= 360.0, x - 360.0, x)  # mod can round up to the period
    if uniform:
        k = jnp.floor(x / widths[0]).astype(jnp.int32)
    else:
        k = jnp.searchsorted(offsets, x, side="right", method="compare_all").astype(jnp.int32) - 1
    k = jnp.clip(k, 0, s - 1)
    return k, (x - offsets[k]) / widths[k]


def cubic(c, t, *, slope: bool = False):
    """``c0 + t (c1 + t (c2 + t c3))`` for coefficients `c` ``(4, *t.shape, ...)`` at `t`
    (broadcast over `c`'s trailing axes), and with `slope` its derivative in `t` too: the
    one evaluation of a cubic piece that the direction splines, the profile-parameter
    weights, `lidarjax.invert`, `invert_joint` and `lidarjax.calibrate` share."""
    t = t.reshape(t.shape + (1,) * (c.ndim - 1 - t.ndim))
    value = c[0] + t * (c[1] + t * (c[2] + t * c[3]))
    if not slope:
        return value
    return value, c[1] + t * (2.0 * c[2] + 3.0 * t * c[3])


def spline_at(geom, coefficients, direction, index=(), *, slope: bool = False):
    """A periodic direction spline's values at `direction` (degrees, any real, shape
    ``(...)``): `geom` ``(start, offsets, widths, uniform)`` and `coefficients` ``(4, s,
    ...)`` of a `PeriodicSpline`; `index` picks trailing entries per direction (e.g. the
    height of each problem). With `slope` also the derivative per degree of direction."""
    start, offsets, widths, uniform = geom
    k, t = locate(start, offsets, widths, uniform, direction)
    c = coefficients[(slice(None), k) + tuple(index)]
    if not slope:
        return cubic(c, t)
    value, dt = cubic(c, t, slope=True)
    w = widths[k]
    return value, dt / w.reshape(w.shape + (1,) * (dt.ndim - w.ndim))


def tabulated_start(w, los, values, spec: str, lead: int):
    """The dense start of the inversions: for each problem, the tabulated entry whose
    closed-form nonnegative speed ``u_k = (sum w los R_k) / (sum w R_k^2)`` fits best, and
    that speed. ``einsum(spec, w * los, values)`` gives the correlations with `lead` leading
    problem axes, the rest (flattened) running over the tabulated entries. Returns the
    entry's flat index and ``u_k`` ``(*lead axes)``."""
    a = jnp.einsum(spec, w * los, values, precision=jax.lax.Precision.HIGHEST)
    c = jnp.einsum(spec, w, values * values, precision=jax.lax.Precision.HIGHEST)
    # the entries' count spelled out, not -1: an empty batch (no problems) stays reshapeable
    entries = math.prod(a.shape[lead:])
    a = a.reshape(a.shape[:lead] + (entries,))
    c = c.reshape(c.shape[:lead] + (entries,))
    uk = jnp.where((a > 0) & (c > 0), a / jnp.where(c > 0, c, 1.0), 0.0)
    k = jnp.argmax(a * uk, axis=-1)
    return k, jnp.take_along_axis(uk, k[..., None], axis=-1)[..., 0]


class PeriodicSpline(eqx.Module):
    """A periodic cubic spline over direction (period 360 degrees) of arrays of any shape.

    Built by `ResponseTable` (coefficients precomputed on the host); call it with directions in
    degrees ``(...)`` to get ``(..., *trailing)``. Continuous with two continuous derivatives;
    differentiable in the direction and in its coefficients. Any real direction is accepted
    (it is wrapped), so there is no domain to leave.

    - `start`: the first knot, degrees in ``[0, 360)``.
    - `offsets`: ``(s,)`` knots minus `start`, increasing from 0, degrees.
    - `widths`: ``(s,)`` interval widths (the last one wraps to ``start + 360``), degrees.
    - `coefficients`: ``(4, s, *trailing)`` cubic coefficients in ``t = (x - knot) / width``.
    - `uniform`: equal widths, so the interval is found by a floor, not a search (static).
    """

    start: Float[Array, ""]
    offsets: Float[Array, " s"]
    widths: Float[Array, " s"]
    coefficients: Float[Array, "4 s ..."]
    uniform: bool = eqx.field(static=True)

    @compiled
    def __call__(self, direction: Float[ArrayLike, ...]) -> Float[Array, ...]:
        """Values at `direction` (degrees): shape ``direction.shape + trailing``."""
        direction = jnp.asarray(direction, self.start.dtype)
        k, t = locate(self.start, self.offsets, self.widths, self.uniform, direction)
        return cubic(self.coefficients[:, k], t)

    @compiled
    def per_row(self, direction: Float[ArrayLike, "... n"]) -> Float[Array, "... n"]:
        """Values with one direction per entry of the first trailing axis (per height):
        `direction` ``(..., n)`` with ``n = trailing[0]`` gives ``(..., n, *trailing[1:])``."""
        direction = jnp.asarray(direction, self.start.dtype)
        n = self.coefficients.shape[2]
        if direction.ndim < 1 or direction.shape[-1] != n:
            raise ValueError(
                f"PeriodicSpline.per_row: `direction` must be shaped (..., {n}), got "
                f"{direction.shape}."
            )
        k, t = locate(self.start, self.offsets, self.widths, self.uniform, direction)
        return cubic(self.coefficients[:, k, jnp.arange(n)], t)

    def derivative(self, direction: Float[ArrayLike, ...]) -> Float[Array, ...]:
        """Derivative with respect to direction, per degree: ``direction.shape + trailing``."""
        direction = jnp.asarray(direction, self.start.dtype)
        return jax.jvp(self.__call__, (direction,), (jnp.ones_like(direction),))[1]


def _fit(knots: np.ndarray, values: np.ndarray, dtype) -> PeriodicSpline:
    """Spline through `values` ``(s, ...)`` at sorted unique `knots` in ``[0, 360)``."""
    values = np.where(np.isnan(values), 0.0, values)  # all-NaN columns: masked by the table
    coefficients = _spline_coefficients(knots, values)
    widths = np.diff(np.append(knots, knots[0] + 360.0))
    uniform = bool(np.allclose(widths, widths[0], rtol=0.0, atol=1e-9))
    return PeriodicSpline(
        jnp.asarray(knots[0], dtype),
        jnp.asarray(knots - knots[0], dtype),
        jnp.asarray(widths, dtype),
        jnp.asarray(coefficients, dtype),
        uniform,
    )


def _dtype_of(value):
    """A float32 (or other non-float64) input keeps its dtype; the rest get the default float."""
    dt = getattr(value, "dtype", None)
    if dt is not None and jnp.issubdtype(dt, jnp.floating) and dt != np.float64:
        return jnp.dtype(dt)
    return default_float()


def _check_columns(name: str, arr: np.ndarray, knots: np.ndarray) -> None:
    """NaN must be the same for every direction (a beam point inside a solid in every run)."""
    nan = np.isnan(arr)
    partial = nan.any(axis=0) & ~nan.all(axis=0)
    if partial.any():
        idx = np.argwhere(partial)[0]
        s = int(np.argmax(nan[(slice(None),) + tuple(idx)]))
        raise ValueError(
            f"ResponseTable: `{name}` is NaN at direction {knots[s]:g} deg, index {tuple(idx)} "
            f"(height, beam, ...) but finite at other directions; a spline cannot interpolate "
            f"it. Drop that height/beam from every run or fix the CFD sampling there."
        )
    if np.isinf(arr).any():
        raise ValueError(f"ResponseTable: `{name}` contains inf.")


@eqx.filter_jit
def _sample_local(field, points):
    return field.sample_local(points)


@eqx.filter_jit
def _gradient_along(field, origin_local, directions, ranges, probe):
    with jax.default_matmul_precision("highest"):
        return gradient_along_beams(field, origin_local, directions, ranges, probe)


def _sorted_directions(directions, response):
    """The table's directions checked and wrapped to ``[0, 360)``: the sort `order`, the
    sorted `knots` (degrees) and `response` ``(s, h, b)`` checked (host float64, unsorted)."""
    d = _host_float(directions, "directions")
    r = _host_float(response, "response")
    if d.ndim != 1 or d.size < 3:
        raise ValueError(
            f"ResponseTable: `directions` must be a 1-D array of at least 3 inflow directions "
            f"in degrees, got shape {d.shape}."
        )
    if not np.all(np.isfinite(d)):
        raise ValueError(
            f"ResponseTable: `directions` must be finite degrees, got {d.tolist()}."
        )
    if r.ndim != 3 or r.shape[0] != d.size:
        raise ValueError(
            f"ResponseTable: `response` must be shaped (s, h, b) = ({d.size}, heights, beams) "
            f"for {d.size} directions, got shape {r.shape}."
        )
    if r.shape[1] == 0 or r.shape[2] == 0:
        raise ValueError(f"ResponseTable: `response` has no heights or beams: {r.shape}.")
    wrapped = np.mod(d, 360.0)
    wrapped = np.where(wrapped >= 360.0, 0.0, wrapped)
    order = np.argsort(wrapped, kind="stable")
    knots = wrapped[order]
    gaps = np.diff(np.append(knots, knots[0] + 360.0))
    if np.any(gaps <= DUPLICATE_TOL):
        k = int(np.argmin(gaps))
        raise ValueError(
            f"ResponseTable: `directions` must be unique modulo 360; {knots[k]:g} deg appears "
            f"twice (e.g. 0 and 360). Drop or average the duplicate runs."
        )
    return order, knots, r


def _optional_column(name, value, shape, order, knots, dtype, response_shape):
    """An optional per-direction array of a table, checked against `shape`, sorted by
    `order` and fitted: ``(array, spline)``, or ``(None, None)`` without one."""
    if value is None:
        return None, None
    a = _host_float(value, name)
    if a.shape != shape:
        raise ValueError(
            f"ResponseTable: `{name}` must be shaped {shape} to match `response` "
            f"(s, h, b) = {response_shape}; got {a.shape}."
        )
    a = a[order]
    _check_columns(name, a, knots)
    return jnp.asarray(a, dtype), _fit(knots, a, dtype)


def _checked_beam_vectors(beam_vectors, b: int, dtype):
    """`beam_vectors` ``(b, 3)`` unit vectors (north frame) or None."""
    if beam_vectors is None:
        return None
    n = _host_float(beam_vectors, "beam_vectors")
    if n.shape != (b, 3) or not np.allclose(np.linalg.norm(n, axis=-1), 1.0, atol=1e-6):
        raise ValueError(
            f"ResponseTable: `beam_vectors` must be ({b}, 3) unit vectors (north frame), "
            f"got shape {n.shape}."
        )
    return jnp.asarray(n, dtype)


def _checked_heights(heights, h: int, dtype):
    """`heights` ``(h,)`` metres or None."""
    if heights is None:
        return None
    hh = _host_float(heights, "heights")
    if hh.shape != (h,):
        raise ValueError(
            f"ResponseTable: `heights` must be shaped ({h},), got {hh.shape}."
        )
    return jnp.asarray(hh, dtype)


class ResponseTable(eqx.Module):
    """What a lidar measures per unit free-stream speed, tabulated against inflow direction.

    **Arguments:**

    - `directions`: ``(s,)`` free-stream directions of the CFD runs, meteorological degrees
      (from, clockwise from north); any order and spacing, unique modulo 360, at least 3.
    - `response`: ``(s, h, b)`` LOS per unit free-stream speed (dimensionless) at each
      height and beam. A height/beam that is NaN for *every* direction (a beam point inside a
      solid) is kept as a missing beam; NaN for only some directions is an error.
    - `reconstructed`: optional ``(s, h, 3)`` the instrument's reconstructed vector per unit
      free-stream speed, north frame (for `lidarjax.invert_reconstructed` and the roses).
    - `point`: optional ``(s, h, 3)`` velocity on the vertical above the lidar per unit
      free-stream speed, north frame (ZephyCube's centre line).
    - `beam_velocity`: optional ``(s, h, b, 3)`` velocity at the beam points per unit speed,
      north frame (ZephyCube's scalar correction).
    - `beam_vectors`: optional ``(b, 3)`` beam unit vectors, north frame.
    - `beam_gradient`: optional ``(s, h, b, 3, 3)`` velocity gradient along each beam per
      unit free-stream speed, north frame, 1/m: ``[..., i, j] = dV_i / dx_j`` weighted over
      the probe volume as `lidarjax.beam_gradient` defines it (the first-order change of
      the LOS when a beam turns by ``dn`` about the lidar is ``dn . V + rho n . (G dn)``,
      ``rho`` the focus range). `lidarjax.calibrate` needs it to model how a tilt moves
      the measurement points; `from_simulations` computes it from the runs' `fields`.
    - `heights`: optional ``(h,)`` measurement heights above the lidar, m.
    - `instrument`: optional `Instrument`, the scan and installation the runs simulated
      (static metadata; `from_simulations` and `lidarjax.build_table` fill it, and
      `lidarjax.io.save_table` writes it), so records from another instrument are refused.

    The table is stored sorted by direction in ``[0, 360)``; the dtype follows `response`
    (float32 stays float32, anything else becomes the default float). Build tables outside
    `jit` (the spline coefficients are computed on the host). Raises `ValueError` for bad
    shapes, duplicate directions, or NaN patterns a spline cannot honour.

    Evaluate with `response_at` etc.; the splines themselves (`response_spline`, ...) are
    `PeriodicSpline`s with the height axis first in their trailing shape.
    """

    directions: Float[Array, " s"]
    response: Float[Array, "s h b"]
    valid: Bool[Array, "h b"]
    reconstructed: Float[Array, "s h 3"] | None
    point: Float[Array, "s h 3"] | None
    beam_velocity: Float[Array, "s h b 3"] | None
    beam_vectors: Float[Array, "b 3"] | None
    beam_gradient: Float[Array, "s h b 3 3"] | None
    heights: Float[Array, " h"] | None
    instrument: Instrument | None = eqx.field(static=True)
    response_spline: PeriodicSpline
    reconstructed_spline: PeriodicSpline | None
    point_spline: PeriodicSpline | None
    beam_velocity_spline: PeriodicSpline | None
    beam_gradient_spline: PeriodicSpline | None

    def __init__(
        self,
        directions: Float[ArrayLike, " s"],
        response: Float[ArrayLike, "s h b"],
        *,
        reconstructed: Float[ArrayLike, "s h 3"] | None = None,
        point: Float[ArrayLike, "s h 3"] | None = None,
        beam_velocity: Float[ArrayLike, "s h b 3"] | None = None,
        beam_vectors: Float[ArrayLike, "b 3"] | None = None,
        beam_gradient: Float[ArrayLike, "s h b 3 3"] | None = None,
        heights: Float[ArrayLike, " h"] | None = None,
        instrument: Instrument | None = None,
    ):
        dtype = _dtype_of(response)
        if instrument is not None and not isinstance(instrument, Instrument):
            raise ValueError("ResponseTable: `instrument` must be a lidarjax.Instrument "
                             "(Instrument.of(scan, mount, heights, probe)) or None.")
        self.instrument = instrument
        order, knots, r = _sorted_directions(directions, response)
        s, h, b = r.shape
        r = r[order]
        _check_columns("response", r, knots)
        self.directions = jnp.asarray(knots, dtype)
        self.response = jnp.asarray(r, dtype)
        self.valid = host_array(~np.isnan(r).all(axis=0))
        self.response_spline = _fit(knots, r, dtype)

        def optional(name, value, shape):
            return _optional_column(name, value, shape, order, knots, dtype, r.shape)

        self.reconstructed, self.reconstructed_spline = optional(
            "reconstructed", reconstructed, (s, h, 3)
        )
        self.point, self.point_spline = optional("point", point, (s, h, 3))
        self.beam_velocity, self.beam_velocity_spline = optional(
            "beam_velocity", beam_velocity, (s, h, b, 3)
        )
        self.beam_gradient, self.beam_gradient_spline = optional(
            "beam_gradient", beam_gradient, (s, h, b, 3, 3)
        )
        self.beam_vectors = _checked_beam_vectors(beam_vectors, b, dtype)
        self.heights = _checked_heights(heights, h, dtype)

    # ----------------------------------------------------------------------------------------
    @property
    def n_directions(self) -> int:
        """Number of tabulated directions ``s``."""
        return self.directions.shape[0]

    @property
    def n_heights(self) -> int:
        """Number of heights ``h``."""
        return self.response.shape[1]

    @property
    def n_beams(self) -> int:
        """Number of beams ``b``."""
        return self.response.shape[2]

    @property
    def dtype(self):
        """Floating dtype of the table."""
        return self.response.dtype

    def _need(self, spline, name):
        if spline is None:
            raise ValueError(
                f"ResponseTable: this table has no `{name}`; build it with `{name}=...` or with "
                f"ResponseTable.from_simulations(...)"
                + (" and `mount=`/`fields=`." if name in ("point", "beam_velocity") else ".")
            )
        return spline

    @compiled
    def response_at(self, direction: Float[ArrayLike, ...]) -> Float[Array, "... h b"]:
        """LOS per unit free-stream speed at meteorological `direction` (degrees, one per
        record, the same for all heights): ``(..., h, b)``; NaN for missing beams."""
        out = self.response_spline(direction)
        return jnp.where(self.valid, out, jnp.nan)

    def reconstructed_at(self, direction: Float[ArrayLike, ...]) -> Float[Array, "... h 3"]:
        """Instrument's reconstructed vector per unit free-stream speed, north frame."""
        return self._need(self.reconstructed_spline, "reconstructed")(direction)

    def point_at(self, direction: Float[ArrayLike, ...]) -> Float[Array, "... h 3"]:
        """Velocity on the vertical above the lidar per unit free-stream speed, north frame."""
        return self._need(self.point_spline, "point")(direction)

    def beam_velocity_at(self, direction: Float[ArrayLike, ...]) -> Float[Array, "... h b 3"]:
        """Velocity at the beam points per unit free-stream speed, north frame."""
        return self._need(self.beam_velocity_spline, "beam_velocity")(direction)

    def centre_projection_at(self, direction: Float[ArrayLike, ...]) -> Float[Array, "... h b"]:
        """Centre-line velocity projected on each beam, per unit free-stream speed: the
        numerator of ZephyCube's per-beam speed-up (`response_at` is the denominator)."""
        if self.beam_vectors is None:
            raise ValueError(
                "ResponseTable: this table has no `beam_vectors`; pass `mount=` to "
                "ResponseTable.from_simulations (or `beam_vectors=`)."
            )
        p = self.point_at(direction)
        # full float32 on GPUs (not TensorFloat-32): see `lidarjax.forward._simulate`
        return jnp.einsum("...hk,bk->...hb", p, self.beam_vectors,
                          precision=jax.lax.Precision.HIGHEST)

    # ----------------------------------------------------------------------------------------
    @classmethod
    def from_simulations(
        cls,
        sims: Simulation | Sequence[Simulation],
        *,
        mount: Mount | Sequence[Mount] | None = None,
        fields: Sequence | None = None,
        scan: Scan | None = None,
        probe: AbstractProbe | None = None,
        instrument: Instrument | None = None,
        beam_gradient: Float[ArrayLike, "s h b 3 3"] | None = None,
        beam_velocity: Float[ArrayLike, "s h b 3"] | None = None,
    ) -> ResponseTable:
        """A table from `lidarjax.simulate` results, one per CFD run (inflow direction).

        **Arguments:**

        - `sims`: a sequence of `Simulation`s (or one `Simulation` whose arrays carry a
          leading run axis, e.g. from `jax.vmap`), each made with ``u_ref`` (the run's free
          stream) and the same heights and beams.
        - `mount`: the `Mount` of the runs (or one per run, for runs that rotate the
          platform by ``beta`` instead of the inflow). Needed for `beam_vectors` (and so the
          centre-line projections of ZephyCube's vector correction) and for `fields`.
        - `fields`: optional sequence of the runs' fields (one per run); the velocity at the
          beam points is sampled from them for ZephyCube's scalar correction, and the
          velocity gradient along the beams (`beam_gradient`, for `lidarjax.calibrate`) is
          taken from them by forward-mode differentiation, over `probe`'s volume (its
          nodes chosen for each field as `simulate` chooses them when `scan` is given).
        - `beam_gradient`: the runs' `lidarjax.beam_gradient` ``(s, h, b, 3, 3)`` (north
          frame, 1/s) when they were computed while the fields were loaded (as
          `lidarjax.build_table` does); divided by the free-stream speed here. Not with
          `fields`.
        - `beam_velocity`: likewise the runs' velocity at the beam points ``(s, h, b, 3)``
          (north frame, m/s), taken while the fields were loaded (`TableRuns` does); needs
          `mount`, not with `fields`.
        - `scan`, `probe`: the scan and probe the runs used: with them the table knows its
          `Instrument` (cone angle, beams, heights, and the mounts' epsilon and tilt), or give
          `instrument` directly.

        Each run gives direction ``wind_direction(free_velocity)`` and, divided by
        ``horizontal_speed(free_velocity)``: `response` from ``los``, `reconstructed` from
        ``lidar_velocity`` and `point` from ``point_velocity`` (all north frame).
        """
        stacked = _stacked_runs(sims)
        speed, directions, heights = _free_streams(stacked)
        s = speed.shape[0]
        dtype = stacked.los.dtype
        norm = lambda a: np.asarray(a, np.float64) / speed.reshape((s,) + (1,) * (a.ndim - 1))  # noqa: E731
        response = norm(stacked.los)
        reconstructed = norm(stacked.lidar_velocity)
        point = None if stacked.point_velocity is None else norm(stacked.point_velocity)
        beam_vectors, gradient = None, None
        if beam_gradient is not None:
            if fields is not None:
                raise ValueError("ResponseTable.from_simulations: give `fields` or "
                                 "`beam_gradient`, not both.")
            gradient = norm(np.asarray(beam_gradient, np.float64))
        if beam_velocity is not None and (fields is not None or mount is None):
            raise ValueError("ResponseTable.from_simulations: `beam_velocity` needs `mount` "
                             "and replaces `fields`; give one of them.")
        if mount is not None:
            mounts, rot, beam_vectors = _north_beams(mount, stacked, s)
            if beam_velocity is not None:
                beam_velocity = norm(np.asarray(beam_velocity, np.float64))
            if fields is not None:
                vel, grad = _sampled_along_beams(fields, mounts, stacked, heights, scan, probe)
                beam_velocity = norm(np.einsum("sij,shbj->shbi", rot, vel))
                gradient = norm(np.einsum("sik,shbkl,sjl->shbij", rot, grad, rot))
        elif fields is not None:
            raise ValueError(
                "ResponseTable.from_simulations: `fields` needs `mount` to rotate the sampled "
                "velocities into the north frame."
            )
        cast = lambda a: None if a is None else np.asarray(a).astype(dtype)  # noqa: E731
        return cls(
            directions,
            cast(response),
            reconstructed=cast(reconstructed),
            point=cast(point),
            beam_velocity=cast(beam_velocity),
            beam_vectors=cast(beam_vectors),
            beam_gradient=cast(gradient),
            heights=cast(heights[0]),
            instrument=instrument if instrument is not None or scan is None
            else Instrument.of(scan, mount, heights[0], probe),
        )


# ------------------------------------------------------------------------------------------
# The steps of `ResponseTable.from_simulations`


def _stacked_runs(sims) -> Simulation:
    """The runs as one `Simulation` with a leading run axis (one given stacked, or a list)."""
    if isinstance(sims, Simulation):
        if sims.los.ndim != 3:
            raise ValueError(
                "ResponseTable.from_simulations: a single Simulation must carry a leading "
                "run axis (los shaped (s, h, b)); pass a list of Simulations otherwise."
            )
        return sims
    sims = list(sims)
    if not sims or not all(isinstance(x, Simulation) for x in sims):
        raise ValueError(
            "ResponseTable.from_simulations: `sims` must be a non-empty sequence of "
            "lidarjax.Simulation."
        )
    shapes = {tuple(x.los.shape) for x in sims}
    if len(shapes) != 1:
        raise ValueError(
            f"ResponseTable.from_simulations: every run needs the same heights and beams; "
            f"got LOS shapes {sorted(shapes)}."
        )
    # on the host: one device program per leaf shape otherwise (the table is host arrays)
    return jax.tree_util.tree_map(lambda *a: np.stack([np.asarray(x) for x in a]), *sims)


def _free_streams(stacked: Simulation):
    """Each run's horizontal free-stream speed ``(s,)`` (m/s) and meteorological direction
    ``(s,)`` (degrees), and the heights ``(s, h)`` (float64), checked."""
    if stacked.free_velocity is None:
        raise ValueError(
            "ResponseTable.from_simulations: the simulations carry no free stream; run "
            "lidarjax.simulate(..., u_ref=...) with each run's free-stream vector."
        )
    free = np.asarray(stacked.free_velocity, np.float64)
    speed = np.asarray(horizontal_speed(free))
    if not np.all(speed > 0):
        raise ValueError(
            "ResponseTable.from_simulations: every run needs a nonzero horizontal free "
            "stream (u_ref) to normalise by."
        )
    heights = np.asarray(stacked.heights, np.float64)
    if not np.allclose(heights, heights[:1]):
        raise ValueError("ResponseTable.from_simulations: the runs have different heights.")
    return speed, np.asarray(wind_direction(free)), heights


def _north_beams(mount, stacked: Simulation, s: int):
    """The runs' mounts (a list of `s`), their CFD-to-north rotations ``(s, 3, 3)`` and the
    beams' unit vectors in the north frame ``(b, 3)``, which every run must share."""
    batched = None
    if isinstance(mount, Mount):
        if mount.batch_shape:  # split on the host: not one device slice per leaf
            mount = batched = jax.tree_util.tree_map(np.asarray, mount)
        mounts = list(mount) if mount.batch_shape else [mount] * s
    else:
        mounts = list(mount)
    if len(mounts) != s or not all(isinstance(m, Mount) for m in mounts):
        raise ValueError(
            f"ResponseTable.from_simulations: `mount` must be a Mount or {s} Mounts."
        )
    rot = np.asarray(jax.vmap(cfd_to_north_rotation)(batched), np.float64) if (
        batched is not None) else np.stack(
        [np.asarray(cfd_to_north_rotation(m), np.float64) for m in mounts])
    dirs = np.asarray(stacked.directions, np.float64)  # (s, b, 3) CFD frame
    n_north = np.einsum("sij,sbj->sbi", rot, dirs)
    if not np.allclose(n_north, n_north[:1], atol=1e-6):
        raise ValueError(
            "ResponseTable.from_simulations: the beams point in different north-frame "
            "directions in different runs; check the mounts (epsilon, psi, beta, gamma)."
        )
    return mounts, rot, n_north[0]


def _sampled_along_beams(fields, mounts, stacked: Simulation, heights, scan, probe):
    """The velocity at the beam points ``(s, h, b, 3)`` and its gradient along the beams
    ``(s, h, b, 3, 3)`` (CFD frame, float64) sampled from each run's field, over `probe`'s
    volume (its nodes chosen per field as `simulate` does when `scan` is given)."""
    fields = list(fields)
    s = len(mounts)
    if len(fields) != s:
        raise ValueError(
            f"ResponseTable.from_simulations: `fields` needs one field per run ({s})."
        )
    # the beam points in float64 from the mounts (`Simulation.points` are rounded
    # to the working dtype: a 0.03-0.5 m grid at UTM coordinates in float32), made
    # relative to each field's origin before rounding
    ranges = np.asarray(stacked.ranges, np.float64)  # (s, h, b), tilt-independent
    dirs = np.asarray(stacked.directions, np.float64)  # (s, b, 3) CFD frame
    vel, grad = [], []
    for i, f in enumerate(fields):
        m = mounts[i]
        loc = np.asarray(m.location, np.float64) + np.asarray(m.location_lo, np.float64)
        origin = np.asarray(f.origin, np.float64) + np.asarray(f.origin_lo, np.float64)
        local = (loc - origin) + ranges[i][..., None] * dirs[i][None]
        vel.append(np.asarray(_sample_local(f, jnp.asarray(local.astype(f.dtype))),
                              np.float64))
        p = PointProbe() if probe is None else probe
        if scan is not None:
            p = probe_for_field(f, scan, heights[i], p, mount=m,
                                caller="ResponseTable.from_simulations")
        to_f = lambda a, f=f: jnp.asarray(np.asarray(a).astype(f.dtype))  # noqa: E731
        grad.append(np.asarray(_gradient_along(
            f, to_f(loc - origin), to_f(dirs[i]), to_f(ranges[i]), p), np.float64))
    return np.stack(vel), np.stack(grad)


# ------------------------------------------------------------------------------------------
# The runs behind a table, to build it again for another installation


class TableRuns(eqx.Module):
    """The CFD runs a `ResponseTable` is built from, kept so that the table can be built
    again for the instrument turned and tilted from its nominal installation
    (`lidarjax.calibrate` does, to iterate on the exact geometry).

    **Arguments:**

    - `fields`: one field per run (inflow direction), or one field shared by every run (a
      single CFD run whose direction is varied by turning the platform, ``Mount.beta``).
    - `mount`: the nominal installation of every run: one `Mount`, or one per run (a
      batched `Mount` or a sequence).
    - `u_ref`: ``(s, 3)`` (or ``(3,)`` shared) each run's free-stream velocity in its CFD
      frame, m/s (`simulate`'s ``u_ref``): it gives the run's direction and normalises it.
    - `scan`: the profiling `Scan`; `heights`: ``(h,)`` m above the lidar; `probe`: the
      probe volume (default the point probe). Its nodes are chosen once, for the field and
      the nominal mounts (`probe_for_field`), and kept for every installation, so that
      tables at different installations differ by the geometry only.

    `table(offset)` is `ResponseTable.from_simulations` of the runs with the velocity at the
    beam points and the beam gradient, the whole set of runs one compiled program (reused
    for every offset: the angles are dynamic).
    """

    fields: Any
    shared_field: bool = eqx.field(static=True)
    mounts: Mount
    u_ref: Float[Array, "s 3"]
    scan: Scan
    heights: Float[Array, " h"]
    probe: AbstractProbe
    user_probe: AbstractProbe | None = eqx.field(static=True)

    def __init__(self, fields, mount, u_ref, scan: Scan, heights, probe=None):
        name = "TableRuns"
        if isinstance(fields, Sequence) and not hasattr(fields, "sample_local"):
            fields = list(fields)
            if not fields:
                raise ValueError(f"{name}: `fields` is empty; give one field per run or one "
                                 "field for every run.")
        if isinstance(mount, Mount):
            mounts = list(mount) if mount.batch_shape else None
        else:
            mounts = list(mount)
            if not mounts or not all(isinstance(m, Mount) for m in mounts):
                raise ValueError(f"{name}: `mount` must be a lidarjax.Mount or a sequence of "
                                 "them (one per run).")
        if not isinstance(scan, Scan):
            raise ValueError(f"{name}: `scan` must be a profiling lidarjax.Scan "
                             f"(lidarjax.windcube_v2(), ...), got {type(scan).__name__}.")
        hh = np.atleast_1d(np.asarray(heights, np.float64))
        if hh.ndim != 1 or not hh.size or not np.all(np.isfinite(hh) & (hh > 0)):
            raise ValueError(f"{name}: `heights` must be finite positive metres above the "
                             f"lidar, shaped (h,); got {hh.tolist()}.")
        u = np.asarray(u_ref, np.float64)
        counts = {len(x) for x in (fields, mounts) if isinstance(x, list)}
        if u.ndim == 2:
            counts.add(u.shape[0])
        if len(counts) > 1:
            raise ValueError(f"{name}: `fields`, `mount` and `u_ref` must give the same number "
                             f"of runs; got {sorted(counts)}.")
        s = counts.pop() if counts else 1
        if s < 3:
            raise ValueError(f"{name}: a table needs at least 3 runs (inflow directions), got "
                             f"{s}.")
        if u.shape not in ((3,), (s, 3)) or not np.all(np.isfinite(u)):
            raise ValueError(f"{name}: `u_ref` must be finite (3,) or ({s}, 3) m/s, got shape "
                             f"{u.shape}.")
        if mounts is None:
            mounts = [mount] * s
        if isinstance(fields, list) and len(fields) == 1:
            fields = fields[0]
        shared = not isinstance(fields, list) or all(f is fields[0] for f in fields)
        if shared and isinstance(fields, list):
            fields = fields[0]
        if not shared:
            first = jax.tree_util.tree_structure(fields[0])
            if any(jax.tree_util.tree_structure(f) != first for f in fields[1:]):
                raise ValueError(f"{name}: the runs' fields differ in kind or shape; give "
                                 "fields of one kind and grid (load every run on one grid).")
            fields = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *fields)
        self.fields = fields
        self.shared_field = shared
        self.mounts = jax.tree_util.tree_map(lambda *a: jnp.stack(a), *mounts)
        self.u_ref = jnp.asarray(np.broadcast_to(u, (s, 3)))
        self.scan = scan
        self.heights = jnp.atleast_1d(jnp.asarray(heights, jnp.result_type(float)))
        self.user_probe = probe
        first_field = fields if shared else jax.tree_util.tree_map(lambda a: a[0], fields)
        self.probe = probe_for_field(first_field, scan, self.heights,
                                     PointProbe() if probe is None else probe,
                                     mount=self.mounts, caller=name)

    def mounts_at(self, offset=(0.0, 0.0, 0.0), north_offset: str = "instrument") -> Mount:
        """The runs' mounts with the instrument turned and tilted by `offset` ``(d_epsilon,
        d_pitch, d_roll)`` degrees from the nominal installation, as `lidarjax.calibrate`
        defines the offsets: pitch and roll grow by ``d_pitch``, ``d_roll``; with
        ``north_offset="instrument"`` the instrument turns on its site so that every beam's
        bearing grows by ``d_epsilon`` (``gamma - d_epsilon``) while its reported north stays
        (``epsilon + d_epsilon``: `lidarjax.frames.cfd_to_north_rotation` unchanged); with
        ``"site"`` the turn is a relabelling of directions and the mounts do not turn.
        Batched over the runs."""
        off = jnp.asarray(offset)
        de = off[0] if north_offset == "instrument" else jnp.zeros_like(off[0])
        m = self.mounts
        return eqx.tree_at(lambda x: (x.gamma, x.epsilon, x.pitch, x.roll), m,
                           (m.gamma - de, m.epsilon + de, m.pitch + off[1], m.roll + off[2]))

    def table(self, offset=(0.0, 0.0, 0.0), north_offset: str = "instrument"
              ) -> ResponseTable:
        """The `ResponseTable` of the instrument at `offset` (degrees, see `mounts_at`) from
        its nominal installation: LOS response, reconstructed vector, point reference, the
        velocity at the beam points and the beam gradient, from `simulate` of every run."""
        if north_offset not in ("instrument", "site"):
            raise ValueError("TableRuns.table: `north_offset` must be 'instrument' or 'site', "
                             f"got {north_offset!r}.")
        dtype = self.u_ref.dtype
        mounts = self.mounts_at(jnp.asarray(offset, dtype), north_offset)
        sims, velocity, gradient = _runs_program(self.fields, self.shared_field, mounts,
                                                 self.u_ref, self.scan, self.heights,
                                                 self.probe)
        return ResponseTable.from_simulations(
            sims, mount=mounts, scan=self.scan, probe=self.user_probe,
            beam_velocity=velocity, beam_gradient=gradient)


@eqx.filter_jit
def _runs_program(fields, shared, mounts, u_ref, scan, heights, probe):
    """Every run of a `TableRuns` at once: the stacked `Simulation`s, the velocity at the
    beam points and the beam gradient (north frame, m/s and 1/s)."""

    def run(field, mount, u):
        sim = simulate(field, scan, mount, heights, u_ref=u, probe=probe)
        velocity, gradient = beam_flow(field, scan, mount, heights, probe)
        return sim, velocity, gradient

    return jax.vmap(run, in_axes=(None if shared else 0, 0, 0))(fields, mounts, u_ref)


# ------------------------------------------------------------------------------------------
# Tables over direction x one inflow-profile parameter


class AbstractProfile(eqx.Module):
    """The free-stream speed profile a `ProfileTable` and `lidarjax.invert_joint` assume:
    the free-stream horizontal speed at height ``z`` is ``U_ref * profile(z, a)``, with
    ``U_ref`` the speed at the reference height and ``a`` the table's profile parameter.

    Subclasses implement ``__call__(heights, parameter)``: `heights` ``(h,)`` m above the
    lidar, `parameter` ``(...)`` (the table's parameter, in its own unit) to a factor
    ``(..., h)``, differentiable in both; and `metadata()` (what a table file stores).
    The choice of profile is static (it is the model); its numbers stay dynamic.
    """

    @abc.abstractmethod
    def __call__(self, heights: Float[ArrayLike, " h"],
                 parameter: Float[ArrayLike, ...]) -> Float[Array, "... h"]:
        raise NotImplementedError

    @abc.abstractmethod
    def metadata(self) -> dict[str, Any]:
        raise NotImplementedError


class PowerLawProfile(AbstractProfile):
    """Power-law shear: ``profile(z, alpha) = (z / reference_height) ** alpha``, the
    parameter being the shear exponent (dimensionless). `reference_height` in m above the
    lidar, positive: the height whose free-stream speed `invert_joint` reports."""

    reference_height: Float[Array, ""]

    def __init__(self, reference_height: Float[ArrayLike, ""]):
        if is_concrete(reference_height):
            z = float(np.asarray(reference_height, np.float64))
            if not (math.isfinite(z) and z > 0):
                raise ValueError(f"PowerLawProfile: `reference_height` must be a positive "
                                 f"height in m, got {reference_height!r}.")
        self.reference_height = jnp.asarray(reference_height, default_float()) \
            if not hasattr(reference_height, "dtype") else jnp.asarray(reference_height)

    def __call__(self, heights, parameter):
        heights = jnp.asarray(heights)
        parameter = jnp.asarray(parameter)
        ratio = heights / self.reference_height.astype(heights.dtype)
        return ratio ** parameter[..., None]

    def metadata(self) -> dict[str, Any]:
        return {"kind": "power_law", "reference_height_m": _host_number(self.reference_height)}


class UniformProfile(AbstractProfile):
    """No profile: ``profile(z, a) = 1``. The parameter changes only the flow distortion
    (a turbulence-intensity class, a stability class whose runs share one inflow profile)."""

    def __call__(self, heights, parameter):
        heights = jnp.asarray(heights)
        parameter = jnp.asarray(parameter)
        return jnp.ones(parameter.shape + heights.shape, heights.dtype)

    def metadata(self) -> dict[str, Any]:
        return {"kind": "uniform"}


def profile_from_metadata(meta: Mapping[str, Any] | None) -> AbstractProfile:
    """The profile a table file's ``profile`` metadata names (`AbstractProfile.metadata`);
    `UniformProfile` for None. Raises `ValueError` for an unknown kind."""
    if meta is None or meta.get("kind") == "uniform":
        return UniformProfile()
    if meta.get("kind") == "power_law":
        return PowerLawProfile(float(meta["reference_height_m"]))
    raise ValueError(f"unknown profile {meta!r}: expected kind 'power_law' (with "
                     "'reference_height_m') or 'uniform'")


def _natural_basis(p: np.ndarray) -> np.ndarray:
    """``(4, P-1, P)``: the natural cubic spline through each unit vector of ``P`` values at
    knots `p` (cardinal functions), as coefficients in ``t = (a - p_k) / (p_{k+1} - p_k)``.
    Two knots give the straight line."""
    n = p.size
    eye = np.eye(n)
    if n == 2:
        c = np.zeros((4, 1, 2))
        c[0, 0], c[1, 0] = eye[0], eye[1] - eye[0]
        return c
    cs = CubicSpline(p, eye, axis=0, bc_type="natural").c  # (4, P-1, P)
    w = np.diff(p)[:, None]
    return np.stack([cs[3], cs[2] * w, cs[1] * w**2, cs[0] * w**3])


def parameter_weights(knots, widths, basis, parameter, *, extrapolate: bool = False):
    """Weights ``(..., P)`` of the ``P`` tabulated values at `parameter` ``(...)``: a
    natural cubic spline inside ``[knots[0], knots[-1]]`` (two continuous derivatives), its
    linear continuation outside (still C2) with `extrapolate`, else NaN outside."""
    n = knots.shape[0]
    parameter = jnp.asarray(parameter, knots.dtype)
    k = jnp.searchsorted(knots, parameter, side="right", method="compare_all") - 1
    k = jnp.clip(k, 0, n - 2)
    t = (parameter - knots[k]) / widths[k]
    tc = jnp.clip(t, 0.0, 1.0)
    value, slope = cubic(basis[:, k], tc, slope=True)  # (..., P)
    w = value + (t - tc)[..., None] * slope
    if not extrapolate:
        w = jnp.where(((t >= 0) & (t <= 1))[..., None], w, jnp.nan)
    return w


class ProfileTable(eqx.Module):
    """A response table over inflow direction x one scalar describing the inflow profile
    (a shear exponent, an Obukhov length, a turbulence-intensity class).

    **Arguments:**

    - `name`: the parameter's name, e.g. ``"alpha"`` (static metadata).
    - `parameters`: ``(p,)`` the parameter values of the CFD runs, increasing, at least 2.
    - `tables`: ``p`` one-parameter `ResponseTable`s, one per value, on the same directions,
      heights and beams (same missing beams), responses per unit **local** free-stream
      speed (see `per_reference_speed`).
    - `profile`: the free-stream profile (`PowerLawProfile`, `UniformProfile` (default), or
      any `AbstractProfile`): the free-stream speed at height ``z`` is
      ``U_ref * profile(z, a)``.
    - `per_reference_speed`: the tables' responses are per unit free-stream speed at the
      reference height (what `from_simulations` gives for a sheared run whose ``u_ref`` is
      the reference-height free stream): they are divided by ``profile(heights, a)`` here.
      Needs the tables' `heights`.

    Interpolation: periodic cubic spline in direction (as `ResponseTable`) and natural cubic
    spline in the parameter (two continuous derivatives; two values give a straight line).
    Dividing out the profile first keeps the parameter dependence weak (the distortion only),
    so few runs interpolate well. Outside the parameter range `response_at` gives NaN unless
    asked to extrapolate (linearly, as `invert_joint` does, with a flag).

    Directions meteorological degrees (from, clockwise from north); north frame.
    """

    name: str = eqx.field(static=True)
    parameters: Float[Array, " p"]
    tables: tuple[ResponseTable, ...]
    profile: AbstractProfile
    parameter_widths: Float[Array, " p1"]
    parameter_basis: Float[Array, "4 p1 p"]
    response_spline: PeriodicSpline
    reconstructed_spline: PeriodicSpline | None

    def __init__(self, name: str, parameters: Float[ArrayLike, " p"],
                 tables: Sequence[ResponseTable], *, profile: AbstractProfile | None = None,
                 per_reference_speed: bool = False):
        if not isinstance(name, str) or not name.isidentifier():
            raise ValueError(f"ProfileTable: `name` must be an identifier such as 'alpha', got "
                             f"{name!r}.")
        p = _host_float(parameters, "parameters").reshape(-1)
        tables = tuple(tables)
        if p.size < 2 or not np.all(np.isfinite(p)) or np.any(np.diff(p) <= 0):
            raise ValueError(f"ProfileTable: `parameters` must be at least 2 finite increasing "
                             f"values of {name}, got {p.tolist()}.")
        if len(tables) != p.size or not all(isinstance(t, ResponseTable) for t in tables):
            raise ValueError(f"ProfileTable: `tables` must be {p.size} ResponseTables, one per "
                             f"value of {name}.")
        profile = UniformProfile() if profile is None else profile
        if not isinstance(profile, AbstractProfile):
            raise ValueError("ProfileTable: `profile` must be a lidarjax.AbstractProfile "
                             "(PowerLawProfile(reference_height) or UniformProfile()).")
        t0 = tables[0]
        for i, t in enumerate(tables[1:], 1):
            if t.response.shape != t0.response.shape or not np.allclose(
                    np.asarray(t.directions), np.asarray(t0.directions), atol=1e-6):
                raise ValueError(
                    f"ProfileTable: the table for {name} = {p[i]:g} has directions or shape "
                    f"{t.response.shape} unlike the first {t0.response.shape}; every profile "
                    "needs runs at the same directions, heights and beams.")
            if not np.array_equal(np.asarray(t.valid), np.asarray(t0.valid)):
                raise ValueError(f"ProfileTable: the table for {name} = {p[i]:g} misses other "
                                 "beams than the first; drop those beams from every table.")
            for attr in ("reconstructed", "point", "beam_velocity", "beam_vectors",
                         "beam_gradient", "heights"):
                if (getattr(t, attr) is None) != (getattr(t0, attr) is None):
                    raise ValueError(f"ProfileTable: `{attr}` is in some tables and not in "
                                     "others; build them alike.")
        if per_reference_speed:
            if t0.heights is None:
                raise ValueError("ProfileTable: `per_reference_speed` needs the tables' heights.")
            tables = tuple(_scaled_table(t, 1.0 / np.asarray(
                profile(np.asarray(t0.heights, np.float64), float(v)), np.float64))
                for t, v in zip(tables, p, strict=True))
            t0 = tables[0]
        dtype = t0.dtype
        self.name = name
        self.tables = tables
        self.profile = profile
        self.parameters = jnp.asarray(p, dtype)
        self.parameter_widths = jnp.asarray(np.diff(p), dtype)
        self.parameter_basis = jnp.asarray(_natural_basis(p), dtype)

        def stacked(attr):
            splines = [getattr(t, attr) for t in tables]
            if splines[0] is None:
                return None
            c = jnp.stack([s.coefficients for s in splines], axis=2)  # (4, s, p, ...)
            s0 = splines[0]
            return PeriodicSpline(s0.start, s0.offsets, s0.widths, c, s0.uniform)

        self.response_spline = stacked("response_spline")
        self.reconstructed_spline = stacked("reconstructed_spline")

    # ----------------------------------------------------------------------------------------
    @property
    def directions(self) -> Float[Array, " s"]:
        """Tabulated directions (degrees, sorted in ``[0, 360)``)."""
        return self.tables[0].directions

    @property
    def response(self) -> Float[Array, "p s h b"]:
        """Tabulated responses per unit local free-stream speed, ``(p, s, h, b)``."""
        return jnp.stack([t.response for t in self.tables])

    @property
    def reconstructed(self) -> Float[Array, "p s h 3"] | None:
        """Tabulated reconstructed vectors per unit local speed, or None."""
        if self.tables[0].reconstructed is None:
            return None
        return jnp.stack([t.reconstructed for t in self.tables])

    @property
    def valid(self) -> Bool[Array, "h b"]:
        return self.tables[0].valid

    @property
    def heights(self) -> Float[Array, " h"] | None:
        return self.tables[0].heights

    @property
    def beam_vectors(self) -> Float[Array, "b 3"] | None:
        return self.tables[0].beam_vectors

    @property
    def instrument(self) -> Instrument | None:
        return self.tables[0].instrument

    @property
    def n_parameters(self) -> int:
        return self.parameters.shape[0]

    @property
    def n_directions(self) -> int:
        return self.tables[0].n_directions

    @property
    def n_heights(self) -> int:
        return self.tables[0].n_heights

    @property
    def n_beams(self) -> int:
        return self.tables[0].n_beams

    @property
    def dtype(self):
        return self.tables[0].dtype

    def weights(self, parameter: Float[ArrayLike, ...], *,
                extrapolate: bool = False) -> Float[Array, "... p"]:
        """Interpolation weights ``(..., p)`` of the tabulated profiles at `parameter`."""
        return parameter_weights(self.parameters, self.parameter_widths, self.parameter_basis,
                                 parameter, extrapolate=extrapolate)

    @compiled
    def response_at(self, direction: Float[ArrayLike, ...], parameter: Float[ArrayLike, ...],
                    *, extrapolate: bool = False) -> Float[Array, "... h b"]:
        """LOS per unit local free-stream speed ``(..., h, b)`` at meteorological `direction`
        (degrees) and profile `parameter` (broadcast together); NaN for missing beams and,
        unless `extrapolate`, outside the parameter range."""
        direction, parameter = jnp.broadcast_arrays(jnp.asarray(direction, self.dtype),
                                                    jnp.asarray(parameter, self.dtype))
        v = self.response_spline(direction)  # (..., p, h, b)
        w = self.weights(parameter, extrapolate=extrapolate)
        out = jnp.einsum("...p,...phb->...hb", w, v, precision=jax.lax.Precision.HIGHEST)
        return jnp.where(self.valid, out, jnp.nan)

    @compiled
    def reconstructed_at(self, direction, parameter, *, extrapolate: bool = False):
        """Reconstructed vector per unit local speed ``(..., h, 3)``, north frame."""
        if self.reconstructed_spline is None:
            raise ValueError("ProfileTable: its tables have no `reconstructed` response.")
        direction, parameter = jnp.broadcast_arrays(jnp.asarray(direction, self.dtype),
                                                    jnp.asarray(parameter, self.dtype))
        v = self.reconstructed_spline(direction)
        w = self.weights(parameter, extrapolate=extrapolate)
        return jnp.einsum("...p,...phk->...hk", w, v, precision=jax.lax.Precision.HIGHEST)

    def at(self, parameter: float) -> ResponseTable:
        """The one-parameter `ResponseTable` at `parameter` (host number inside the range):
        every tabulated array interpolated in the parameter (exact for the splines, which are
        linear in the tabulated values). For `lidarjax.invert` at a known profile."""
        a = float(parameter)
        lo, hi = float(self.parameters[0]), float(self.parameters[-1])
        if not lo <= a <= hi:
            raise ValueError(f"ProfileTable.at: {self.name} = {a:g} is outside the table's "
                             f"range [{lo:g}, {hi:g}].")
        w = np.asarray(self.weights(jnp.asarray(a, self.dtype)), np.float64)
        return _combined(self.tables, w)


def _scaled_table(t: ResponseTable, factor: np.ndarray) -> ResponseTable:
    """`t` with every per-height array multiplied by `factor` ``(h,)``."""
    f = np.asarray(factor, np.float64)

    def sc(a, nd):
        if a is None:
            return None
        a = np.asarray(a, np.float64)
        return (a * f.reshape((1, -1) + (1,) * (nd - 2))).astype(np.asarray(t.response).dtype)

    return ResponseTable(np.asarray(t.directions), sc(t.response, 3),
                         reconstructed=sc(t.reconstructed, 3), point=sc(t.point, 3),
                         beam_velocity=sc(t.beam_velocity, 4),
                         beam_gradient=sc(t.beam_gradient, 5),
                         beam_vectors=None if t.beam_vectors is None else np.asarray(
                             t.beam_vectors),
                         heights=None if t.heights is None else np.asarray(t.heights),
                         instrument=t.instrument)


def _combined(tables: Sequence[ResponseTable], w: np.ndarray) -> ResponseTable:
    """The table whose arrays are ``sum_k w_k tables[k].array``."""
    t0 = tables[0]
    dtype = np.asarray(t0.response).dtype

    def mix(attr):
        if getattr(t0, attr) is None:
            return None
        return sum(wk * np.asarray(getattr(t, attr), np.float64)
                   for wk, t in zip(w, tables, strict=True)).astype(dtype)

    return ResponseTable(np.asarray(t0.directions), mix("response"),
                         reconstructed=mix("reconstructed"), point=mix("point"),
                         beam_velocity=mix("beam_velocity"), beam_gradient=mix("beam_gradient"),
                         beam_vectors=None if t0.beam_vectors is None else np.asarray(
                             t0.beam_vectors),
                         heights=None if t0.heights is None else np.asarray(t0.heights),
                         instrument=t0.instrument)
