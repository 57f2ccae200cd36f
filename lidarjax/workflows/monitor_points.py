"""Let the CFD code interrogate itself: the lidar's sample points as CFD probes, and the
lidar simulated from the values the CFD code sampled there.

The seed UDF samples the CFD solution inside the solver; monitor probes (OpenFOAM's
``probes`` function object, zCFD's ``report``/``monitor`` points) do the same without a
UDF. `monitor_points` lists every point `lidarjax.simulate` would sample for a scan,
mounts, heights and probe volume: each beam's focus (point probe) or its probe-volume
quadrature nodes ahead of the lidar, and (``point_reference=True``) the column above the
lidar. Each point is named ``<mount>_h<height>_beam<b>_q<node>`` (``<mount>_h<height>_point``
for the reference column) so it maps back to the mount (by default ``b<beta>``), the
height, the beam and the node. `lidarjax.io.write_openfoam_probes`,
`lidarjax.io.write_zcfd_probes` and `lidarjax.io.write_monitor_points_csv` write them out.

After the CFD run, `simulate_from_monitor_points` takes the sampled velocities (read with
`lidarjax.io.read_openfoam_probes` or `lidarjax.io.read_monitor_values_csv`) and returns the
very `Simulation` that `lidarjax.simulate` gives in a gridded field: it wraps the samples
of each mount in a `MonitorPointField`, a field that knows the velocity at exactly those points
(NaN anywhere else), and calls `simulate` itself, so the LOS (with the probe weights),
reconstruction, point reference and correction factors are the forward model's own.

Conventions: absolute CFD coordinates in metres, velocities ``(u, v, w)`` in m/s in the
CFD frame; heights in metres above the lidar; beams numbered as the scan's
(``scan.directions()``: Windcube S0, S1, S2, S3, then the vertical beam); quadrature
nodes numbered as ``probe.nodes``.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .._precision import default_float, is_concrete, split
from .._util import format_number
from ..corrections import DEFAULT_RATIO_TOL
from ..field import AbstractField, IndexedPoints, PointIndex
from ..forward import Simulation, simulate
from ..io.monitor_points import FOCUS_FALLBACK, POINT_REFERENCE, MonitorPoints
from ..mount import Mount
from ..probe import AbstractProbe, PointProbe
from ..scan import Scan
from ..scenes import uniform

__all__ = ["MonitorPointField", "MonitorPoints", "monitor_points", "simulate_from_monitor_points"]


def _label_number(x: float) -> str:
    return format_number(float(x))


def _mount_list(mounts) -> list[Mount]:
    if isinstance(mounts, Mount):
        if mounts.location.ndim == 2:
            return [jax.tree_util.tree_map(lambda x, k=k: x[k], mounts)
                    for k in range(mounts.location.shape[0])]
        return [mounts]
    out = list(mounts)
    if not out or not all(isinstance(m, Mount) for m in out):
        raise ValueError("monitor_points: `mounts` must be a lidarjax.Mount or a non-empty "
                         "list of them")
    return out


def _labels(mounts: list[Mount], labels) -> list[str]:
    if labels is None:
        labels = [f"b{_label_number(np.asarray(m.beta))}" for m in mounts]
        if len(set(labels)) != len(labels):
            raise ValueError("monitor_points: several mounts share a beta, so the default "
                             "labels 'b<beta>' repeat; pass labels=['lidar1', 'lidar2', ...]")
    labels = [str(x) for x in labels]
    if len(labels) != len(mounts):
        raise ValueError(f"monitor_points: {len(labels)} labels for {len(mounts)} mounts")
    if len(set(labels)) != len(labels):
        raise ValueError(f"monitor_points: mount labels must be unique, got {labels}")
    bad = [x for x in labels if not x or any(c.isspace() for c in x) or "," in x]
    if bad:
        raise ValueError(f"monitor_points: mount labels must be non-empty without spaces or "
                         f"commas, got {bad}")
    return labels


def _probe_list(probe, n: int, caller: str) -> list[AbstractProbe]:
    """One probe per mount: `probe` (None: the point probe) for every mount, or a sequence
    of one per mount."""
    probes = list(probe) if isinstance(probe, (list, tuple)) else [probe] * n
    if len(probes) != n:
        raise ValueError(f"{caller}: {len(probes)} probes for {n} mounts; give one probe, or "
                         "one per mount")
    probes = [PointProbe() if p is None else p for p in probes]
    bad = [type(p).__name__ for p in probes if not isinstance(p, AbstractProbe)]
    if bad:
        raise ValueError(f"{caller}: `probe` must be a probe (or one per mount), got {bad[0]}")
    return probes


def _geometry(scan: Scan, mounts: list[Mount], heights: np.ndarray):
    """Beam directions ``(m, b, 3)`` (CFD frame) and focus ranges ``(m, h, b)`` in the working
    dtype, taken from `simulate` itself (one compiled call per mount on a uniform flow), so
    the written points are the forward model's own, tilt included."""

    scene = uniform(10.0, 270.0)
    dirs, ranges = [], []
    for m in mounts:
        sim = simulate(scene, scan, m, heights, point_reference=False)
        dirs.append(np.asarray(sim.directions))
        ranges.append(np.asarray(sim.ranges))
    return np.stack(dirs), np.stack(ranges)


def monitor_points(
    scan: Scan,
    mounts: Mount | Sequence[Mount],
    heights: Float[ArrayLike, " h"],
    probe: AbstractProbe | Sequence[AbstractProbe] | None = None,
    *,
    point_reference: bool = True,
    labels: Sequence[str] | None = None,
) -> MonitorPoints:
    """Every point `lidarjax.simulate` samples for these mounts, named, as CFD probes.

    **Arguments:**

    - `scan`, `heights` (metres above the lidar), `probe`, `point_reference`: as given to
      `simulate` (the point probe samples each beam's focus; a probe volume its quadrature
      nodes, except nodes behind the lidar, which get no weight). `probe` with its nodes
      chosen (`lidarjax.probe_for_field` with the mount); one probe for every mount or a
      sequence of one per mount (platform rotations whose beams see other cells get other
      node counts: `lidarjax.workflows.seed_tables.settings_probes`). A `GradedProbe`
      writes every height padded to its largest count, as `lidarjax.beam.simulate_points`
      prepares them: the padding nodes sit at the focus with weight 0.
    - `mounts`: one `Mount`, a list, or a stacked `Mount`.
    - `labels`: one name per mount (default ``b<beta>``, e.g. ``b30``); used as the prefix
      of the probe names.

    **Returns:** `MonitorPoints` (absolute CFD metres, float64), mount by mount, then height,
    beam and node; each mount's point-reference column follows its beams.

    The points are computed by `simulate` in the working dtype (float64 with x64 enabled)
    and made absolute in float64 from the mount's location, so they agree with what
    `simulate` samples to rounding.
    """
    if not isinstance(scan, Scan):
        raise ValueError(f"monitor_points: `scan` must be a lidarjax.Scan, got {type(scan).__name__}")
    mounts = _mount_list(mounts)
    probes = _probe_list(probe, len(mounts), "monitor_points")
    if not is_concrete(scan, mounts, heights, probes):
        raise ValueError("monitor_points: needs concrete inputs (call it outside jax.jit)")
    h = np.atleast_1d(np.asarray(heights, np.float64))
    if h.ndim != 1 or h.size == 0 or not np.all(np.isfinite(h)) or np.any(h <= 0):
        raise ValueError(f"monitor_points: heights must be positive metres, got {h.tolist()}")
    labels = _labels(mounts, labels)
    directions, ranges = _geometry(scan, mounts, h)
    n_beams = directions.shape[1]
    names: list[str] = []
    cols: dict[str, list] = {k: [] for k in ("mount", "points", "beta", "height", "beam", "node",
                                             "weight")}

    def add(label, beta, loc, height, beam, node, weight, local, name):
        names.append(name)
        cols["mount"].append(label)
        cols["points"].append(loc + local)
        cols["beta"].append(beta)
        cols["height"].append(height)
        cols["beam"].append(beam)
        cols["node"].append(node)
        cols["weight"].append(weight)

    for m, (mount, label, probe) in enumerate(zip(mounts, labels, probes, strict=True)):
        loc = np.asarray(mount.location, np.float64) + np.asarray(mount.location_lo, np.float64)
        beta = float(np.asarray(mount.beta))
        r = ranges[m]  # (h, b), working dtype
        d = directions[m]  # (b, 3)
        if isinstance(probe, PointProbe):
            offsets = np.zeros(r.shape + (1,), r.dtype)
            weights = np.ones_like(offsets)
        else:
            o, w = probe.nodes(jnp.asarray(r))
            offsets = np.broadcast_to(np.asarray(o, r.dtype), r.shape + np.shape(o)[-1:])
            weights = np.broadcast_to(np.asarray(w, r.dtype), offsets.shape)
        ahead = np.abs(offsets) < r[..., None]
        if isinstance(probe, PointProbe):
            ahead = np.ones_like(ahead)
        kept = np.where(ahead, weights, 0).astype(np.float64)
        total = kept.sum(-1)
        for i, hi in enumerate(h):
            htag = f"{label}_h{_label_number(hi)}"
            for b in range(n_beams):
                node_ranges = (r[i, b] + offsets[i, b]).astype(r.dtype)  # as simulate rounds
                if total[i, b] <= 0:  # even-count probe entirely behind the lidar
                    add(label, beta, loc, hi, b, FOCUS_FALLBACK, 1.0,
                        np.float64(r[i, b]) * d[b].astype(np.float64), f"{htag}_beam{b}_focus")
                    continue
                for q in np.flatnonzero(ahead[i, b]):
                    local = (node_ranges[q] * d[b]).astype(np.float64)
                    add(label, beta, loc, hi, b, int(q), kept[i, b, q] / total[i, b], local,
                        f"{htag}_beam{b}_q{q}")
            if point_reference:
                add(label, beta, loc, hi, -1, POINT_REFERENCE, np.nan,
                    np.array([0.0, 0.0, hi]), f"{htag}_point")
    return MonitorPoints(
        names=tuple(names), mount=tuple(cols["mount"]),
        points=np.array(cols["points"], np.float64).reshape(-1, 3),
        beta=np.array(cols["beta"], np.float64), height=np.array(cols["height"], np.float64),
        beam=np.array(cols["beam"], np.int64), node=np.array(cols["node"], np.int64),
        weight=np.array(cols["weight"], np.float64))



class MonitorPointField(IndexedPoints, AbstractField):
    """Velocities known at scattered points only: a field that returns the sampled value at
    exactly those points (within `tolerance`) and NaN anywhere else.

    This is how CFD monitor-probe samples go through `lidarjax.simulate`: a query matches
    the nearest stored point when it is within `tolerance` metres of it, so `simulate`
    evaluated at the points of `monitor_points` sees precisely the CFD code's own samples.
    Any other point (e.g. a scan or heights other than those the probes were written for)
    is NaN and flagged by `simulate` (`Flag.BEAM_OUTSIDE` / `POINT_OUTSIDE`).

    **Arguments:**

    - `points`: ``(n, 3)`` absolute CFD coordinates, metres.
    - `velocity`: ``(n, 3)`` sampled ``(u, v, w)``, m/s, CFD frame (NaN: not sampled, e.g.
      outside the mesh). Its floating dtype is the field's working dtype.
    - `origin`: reference point (``(3,)`` CFD metres, or a `Mount`, whose exact location
      is used); default the points' mean. Points are stored relative to it.
    - `tolerance`: match distance, metres; default ``1e-9`` (float64) or ``2e-5`` (float32)
      times the largest distance of a point from `origin` (at least that times one metre).
      Points closer than that are taken as one location (e.g. the vertical beam's focus
      and the point reference above the lidar), whichever of them is nearest.

    The lookup is a `lidarjax.field.PointIndex` (O(log n) per query in memory and time).
    Gradients flow to `velocity`; the lookup itself has no spatial derivative (the field is
    a table).
    """

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    index: PointIndex
    velocity: Float[Array, "n 3"]

    def __init__(self, points, velocity, *, origin=None, tolerance=None):
        pts = np.asarray(points, np.float64)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
            raise ValueError(f"MonitorPointField: points must have shape (n, 3), n >= 1; got {pts.shape}")
        if not np.all(np.isfinite(pts)):
            raise ValueError("MonitorPointField: points must be finite CFD coordinates")
        vel = jnp.asarray(velocity)
        if not jnp.issubdtype(vel.dtype, jnp.floating):
            vel = vel.astype(default_float())
        if vel.shape != pts.shape:
            raise ValueError(f"MonitorPointField: velocity must have shape {pts.shape}, got {vel.shape}")
        dtype = vel.dtype
        if isinstance(origin, Mount):
            hi, lo = origin.location, origin.location_lo
            o64 = np.asarray(hi, np.float64) + np.asarray(lo, np.float64)
            self.origin, self.origin_lo = split(o64, dtype)
        else:
            o64 = pts.mean(axis=0) if origin is None else np.asarray(origin, np.float64).reshape(3)
            self.origin, self.origin_lo = split(o64, dtype)
        self.index = PointIndex.build(pts - o64, dtype, tolerance, caller="MonitorPointField")
        self.velocity = vel

    def sample_local(self, points):
        """Sampled velocity (m/s) at local points matching a stored point, NaN elsewhere."""
        points = jnp.asarray(points).astype(self.dtype)
        best, hit = self.index.match(points)
        v = self.velocity[best]
        ok = hit & jnp.all(jnp.isfinite(v), axis=-1)
        return jnp.where(ok[..., None], jnp.where(ok[..., None], v, 0), jnp.nan)


def _require_names(names, available, what: str, fix: str) -> None:
    """Raise `ValueError` (``N <what>, e.g. <names>; <fix>``) when some `names` are not in
    `available`."""
    missing = [n for n in names if n not in available]
    if missing:
        raise ValueError(f"simulate_from_monitor_points: {len(missing)} {what}, e.g. "
                         f"{', '.join(missing[:4])}; {fix}")


def _aligned_values(locations: MonitorPoints, values) -> np.ndarray:
    """``(n, 3)`` values in the row order of `locations` from an array or a name mapping."""
    if isinstance(values, Mapping):
        _require_names(locations.names, values, f"of {len(locations)} probes have no sampled value",
                       "were the probes written for this scan, probe, heights and mounts?")
        return np.array([np.asarray(values[n], np.float64).reshape(3) for n in locations.names])
    arr = np.asarray(values)
    if arr.shape != (len(locations), 3):
        raise ValueError(f"simulate_from_monitor_points: values must have shape ({len(locations)}, 3) "
                         f"in the probes' order, got {arr.shape}")
    return arr


def simulate_from_monitor_points(
    locations: MonitorPoints,
    values,
    scan: Scan,
    mounts: Mount | Sequence[Mount],
    heights: Float[ArrayLike, " h"],
    *,
    probe: AbstractProbe | Sequence[AbstractProbe] | None = None,
    u_ref=None,
    point_reference: bool = True,
    ratio_tol: float | None = None,
    tolerance: float | None = None,
) -> list[Simulation]:
    """`lidarjax.simulate` from velocities the CFD code sampled at `monitor_points`.

    **Arguments:**

    - `locations`: the `MonitorPoints` the CFD code sampled (as written, or read back with
      `lidarjax.io.read_monitor_points_csv`).
    - `values`: ``(n, 3)`` velocities (m/s, CFD frame) in the order of `locations`, or a
      mapping ``name -> (u, v, w)``; NaN where the CFD code found no cell.
    - `scan`, `mounts`, `heights`, `probe` (one, or one per mount), `point_reference`: the
      configuration the probes were written for (checked: every point `simulate` needs
      must be among `locations`, at the same place).
    - `u_ref`: free stream ``(3,)`` (CFD frame, m/s) for every mount, or ``(m, 3)`` one per
      mount; None for no ``cff_*``.
    - `tolerance`: `MonitorPointField` match distance (metres; default its own).

    **Returns:** one `Simulation` per mount: the forward model run on a `MonitorPointField` of that
    mount's samples, so LOS (with the probe's weights), reconstruction, point reference,
    correction factors and flags are `simulate`'s own. The dtype follows `values` (float64
    numpy input gives float64 with x64 enabled).
    """

    if not isinstance(locations, MonitorPoints):
        raise ValueError("simulate_from_monitor_points: `locations` must be a MonitorPoints "
                         "(lidarjax.monitor_points or lidarjax.io.read_monitor_points_csv)")
    mounts = _mount_list(mounts)
    probes = _probe_list(probe, len(mounts), "simulate_from_monitor_points")
    vals = _aligned_values(locations, values)
    labels = locations.labels
    if len(labels) != len(mounts):
        raise ValueError(f"simulate_from_monitor_points: the probes hold {len(labels)} mount(s) "
                         f"({', '.join(labels[:6])}), but {len(mounts)} mount(s) were given")
    expected = monitor_points(scan, mounts, heights, probes, point_reference=point_reference,
                               labels=labels)
    index = {n: i for i, n in enumerate(locations.names)}
    _require_names(expected.names, index, "point(s) this configuration samples are not among the probes",
                   "write the probes with the same scan, probe, heights and mounts")
    rows = np.array([index[n] for n in expected.names])
    gap = np.linalg.norm(locations.points[rows] - expected.points, axis=1)
    scale = np.maximum(1.0, np.linalg.norm(expected.points - expected.points.mean(0), axis=1))
    bad = np.flatnonzero(gap > 1e-6 * scale)
    if bad.size:
        k = bad[0]
        raise ValueError(
            f"simulate_from_monitor_points: probe {expected.names[k]} was written at "
            f"{locations.points[rows[k]].tolist()} but this configuration samples "
            f"{expected.points[k].tolist()} (mount location or angles differ)")
    vals = vals[rows]
    if u_ref is not None:
        u = np.asarray(u_ref, np.float64)
        u_refs = [u] * len(mounts) if u.shape == (3,) else list(u)
        if len(u_refs) != len(mounts):
            raise ValueError(f"simulate_from_monitor_points: u_ref must be (3,) or ({len(mounts)}, 3)")
    else:
        u_refs = [None] * len(mounts)
    dtype = vals.dtype if np.issubdtype(vals.dtype, np.floating) else np.float64
    sims = []
    for mount, label, u, p in zip(mounts, labels, u_refs, probes, strict=True):
        sel = expected.rows(label)
        field = MonitorPointField(expected.points[sel], vals[sel].astype(dtype),
                           origin=mount, tolerance=tolerance)
        sims.append(simulate(field, scan, mount, heights, u_ref=u, probe=p,
                             point_reference=point_reference,
                             ratio_tol=DEFAULT_RATIO_TOL if ratio_tol is None else ratio_tol))
    return sims
