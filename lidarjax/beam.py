"""The beam: where a lidar's beams go, which nodes along them it samples, and their LOS.

Every path that samples a field along beams calls this module, profilers (`lidarjax.simulate`,
the rotations, `sensitivity`, the series) and scanning patterns (`lidarjax.simulate_scan`,
dual-Doppler) alike:

- **geometry**: `profile_geometry` (a profiling scan's beams in the CFD frame from a `Mount`,
  the mount's tilt included, and their focus ranges ``h / cos(cone)``), `pattern_geometry`
  (a scanning pattern's sub-rays on the host);
- **nodes**: `probe_for_field` (the node count the field's resolution needs, per height where
  the field's spacing varies along the beams: `GradedProbe`), `pattern_probe` and
  `shared_gate_rule` (a scanning pattern's gates), `gate_nodes`;
- **points**: `beam_points`, every point a path samples (absolute CFD metres, host): what an
  exact sampler (`lidarjax.io.cellpoint_field`) or a CFD code's probes
  (`lidarjax.monitor_points`) are prepared at. `lidarjax.io.simulate_points` and
  `lidarjax.scan_points` are its profiler and pattern forms;
- **LOS**: `beam_los` (the probe quadrature along beams, with the symmetric cut at the lidar,
  NaN rules and derivatives) and `gates_los` (equally spaced gates sharing their nodes).

`lidarjax.probe` stays the module of the probe *weighting*: the weightings, their transfer
functions and the quadrature rule of one focus range for one field resolution, with no
beam geometry. Splitting there keeps the probe a plain description of the instrument and
puts everything that depends on where a beam is (directions, the cut at the lidar, the
field's spacing along the support, the points sampled) in one place, so the points an exact
sampler prepares are the points the LOS samples, by construction.

Frames and units: metres, the CFD frame (``x`` east, ``y`` north, ``z`` up unless the mount's
angles say otherwise; `lidarjax.frames`), LOS positive away from the lidar, m/s.
"""

from __future__ import annotations

import functools
import math
import warnings
import weakref

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._backend import is_accelerator
from ._precision import is_concrete
from ._util import ArrayMemo
from .field import AbstractField
from .frames import body_to_cfd_rotation, rotate
from .mount import Mount
from .probe import (
    TRANSFER_TOL,
    AbstractProbe,
    CWProbe,
    PointProbe,
    PulsedProbe,
    host_nodes,
    host_weighting,
    probe_for_ranges,
)
from .scan import Scan

__all__ = ["ExactPoints", "GradedProbe", "beam_los", "beam_points", "gate_nodes", "gate_quadrature",
           "gates_los", "pattern_geometry", "pattern_probe", "probe_for_field",
           "profile_geometry", "scan_points", "shared_gate_rule", "simulate_points"]


# ---------------------------------------------------------------------------------------
# geometry


def profile_geometry(scan: Scan, mount: Mount, heights: Float[Array, " h"]):
    """A profiling scan's beams from one mount (traced, in the dtype of `heights`): unit
    vectors ``(b, 3)`` in the CFD frame (the mount's ``beta + gamma - psi`` and its pitch and
    roll: `lidarjax.body_to_cfd_rotation`) and focus ranges ``(h, b)``, m, ``h / cos(cone)``
    in the body frame (``h`` for a vertical beam) whatever the tilt: the instrument assumes
    it is level. `scan` and `mount` are cast to the dtype of `heights`."""
    dtype = heights.dtype
    cast = lambda a: jnp.asarray(a).astype(dtype)  # noqa: E731
    scan = jax.tree_util.tree_map(cast, scan)
    mount = jax.tree_util.tree_map(cast, mount)
    n_body = scan.directions()  # (b, 3), instrument axes
    n_cfd = rotate(body_to_cfd_rotation(mount), n_body)
    return n_cfd, heights[:, None] / n_body[None, :, 2]


def pattern_geometry(pattern, mount: Mount) -> tuple[np.ndarray, np.ndarray]:
    """Host float64 geometry of `pattern`'s sub-rays from one `mount` (concrete numbers):
    the lidar's location, absolute CFD metres ``(3,)``, and every sub-ray's unit direction in
    the CFD frame ``(B, 3)`` (``B`` = rays x sub-rays, ray-major, as
    `ScanPattern.sub_directions`)."""
    rot = np.asarray(body_to_cfd_rotation(mount), np.float64)
    n = np.asarray(pattern.sub_directions(), np.float64).reshape(-1, 3) @ rot.T  # (B, 3)
    loc = np.asarray(mount.location, np.float64) + np.asarray(mount.location_lo, np.float64)
    return loc, n


# ---------------------------------------------------------------------------------------
# nodes: how many, for the field's resolution where the beam is


class GradedProbe(AbstractProbe):
    """One probe weighting integrated with a node count per group of heights: the nodes
    each height needs for the field's spacing along its beams (`probe_for_field`), so a mesh
    graded to the wall does not give every height the wall's node count.

    **Arguments:**

    - `probes`: the weighting with each node count used (same weighting, `n_nodes` apart;
      a `CWProbe` also carries the spacing its nodes resolve).
    - `groups`: static ``((start, stop, k), ...)``: heights ``start:stop`` (indices into the
      heights the probe was chosen for, in order, covering them all) take ``probes[k]``.

    `lidarjax.beam.beam_los` integrates each group with its own probe and joins them (the
    heights' node counts are static: they set shapes); `nodes` gives the nodes of every
    height padded to the largest count with zero-weight nodes at the focus. Built by
    `probe_for_field`; every number of the weighting stays dynamic.
    """

    probes: tuple[AbstractProbe, ...]
    groups: tuple[tuple[int, int, int], ...] = eqx.field(static=True)

    def __check_init__(self):
        stops = [0] + [g[1] for g in self.groups]
        if not self.groups or any(g[0] != s for g, s in zip(self.groups, stops, strict=False)) \
                or any(not 0 <= g[2] < len(self.probes) for g in self.groups):
            raise ValueError("GradedProbe: `groups` must cover heights 0..h in order, each "
                             "naming one of `probes`.")

    @property
    def n_heights(self) -> int:
        """Number of heights the node counts were chosen for."""
        return self.groups[-1][1]

    @property
    def node_counts(self) -> tuple[int, ...]:
        """Node count of every height (static)."""
        return tuple(n for a, b, k in self.groups for n in [self.probes[k].n_nodes] * (b - a))

    @property
    def n_nodes(self) -> int:
        """The largest node count of any height."""
        return max(p.n_nodes for p in self.probes)

    @property
    def finest(self) -> AbstractProbe:
        """The probe with the most nodes (for paths that need one count at every height)."""
        return max(self.probes, key=lambda p: p.n_nodes)

    @property
    def tail(self):
        """The weighting's `tail` (see `lidarjax.probe`)."""
        return self.probes[0].tail

    def rows(self):
        """``(slice of heights, probe)`` for every group."""
        return [(slice(a, b), self.probes[k]) for a, b, k in self.groups]

    def nodes(self, focus_range):
        """``(offsets, weights)`` ``(h, ..., q)`` of every height (leading axis of
        `focus_range`: the heights), padded to `n_nodes` with weight-0 nodes at the focus."""
        r = jnp.asarray(focus_range)
        if r.ndim == 0 or r.shape[0] != self.n_heights:
            raise ValueError(f"GradedProbe.nodes: focus ranges must have the {self.n_heights} "
                             f"heights on their leading axis, got shape {r.shape}.")
        q = self.n_nodes
        offs, wts = [], []
        for rows, p in self.rows():
            o, w = p.nodes(r[rows])
            o = jnp.broadcast_to(o, r[rows].shape + o.shape[-1:])
            w = jnp.broadcast_to(w, o.shape)
            pad = [(0, 0)] * (o.ndim - 1) + [(0, q - o.shape[-1])]
            offs.append(jnp.pad(o, pad))
            wts.append(jnp.pad(w, pad))
        return jnp.concatenate(offs), jnp.concatenate(wts)

    def weight(self, offset, focus_range=None):
        """The weighting (as its probes')."""
        return self.probes[0].weight(offset, focus_range)

    def support(self, focus_range=None):
        """Half-width of the truncated support (as its probes')."""
        return self.probes[0].support(focus_range)

    def scaled(self, factor) -> GradedProbe:
        """Every probe scaled (see `AbstractProbe.scaled`)."""
        return GradedProbe(tuple(p.scaled(factor) for p in self.probes), self.groups)


#: Share of a beam's weight (the cut weighting's) that `probe_for_field` lets lie where the
#: field is finer than the spacing it resolves: a wave there changes a LOS by at most twice
#: that share, so the nodes are chosen to ``TRANSFER_TOL - 2 * SUPPORT_SHARE`` for the rest.
SUPPORT_SHARE = TRANSFER_TOL / 4

#: Samples per beam where `probe_for_field` reads the field's spacing along the support.
_SUPPORT_SAMPLES = 129

_CHOSEN = ArrayMemo()


def probe_for_field(field: AbstractField, scan: Scan, heights, probe: AbstractProbe,
                    *, mount: Mount | None = None,
                    caller: str = "probe_for_field") -> AbstractProbe:
    """The probe `field` is sampled with: `probe` with its quadrature nodes chosen for the
    field's resolution at the focus ranges of `scan` at `heights` (m), by
    `lidarjax.probe.probe_for_spacing` (transfer function within 0.01 of the weighting's up
    to the field's Nyquist wavenumber, fewest nodes).

    **Arguments:**

    - `field`, `scan`, `heights`, `probe`: as given to `lidarjax.simulate`.
    - `mount`: the lidar's `Mount` (one or a batch). With it, each height gets the nodes
      the field's spacing *along its beams' support* needs
      (`AbstractField.spacing_at`): the spacing that all but `SUPPORT_SHARE` of the cut
      weighting sees, over every beam (and every mount of a batch) at that height, rounded
      down to quarter octaves above the field's finest spacing (heights on one rung share
      one choice), the rule held to ``TRANSFER_TOL - 2 SUPPORT_SHARE`` where that spacing is
      coarser than the finest (a wave in the finer share moves a LOS by at most twice its
      weight). On a mesh graded to the wall, heights
      whose beams see coarse cells get fewer nodes. Where every height would get the count
      of the field's finest spacing (uniform grids, scenes), this is the single count of
      `AbstractField.resolution`, exactly as without a mount. Otherwise the result is a
      `GradedProbe` (node counts per group of heights, static).
    - `caller`: named in the warning when no node count up to
      `lidarjax.probe.MAX_NODES` reaches the tolerance.

    The one place `simulate`, `simulate_rotations`, `sensitivity`, `uncertainty`, the
    response tables built from them and the series choose nodes, all with their mount
    (`beam_points` and `ExactPoints` prepare the same; `simulate_statistics` over an
    ensemble passes none: one count, the finest spacing's, at every height). An
    explicit node count (``PulsedProbe(n_nodes=17)``, `with_nodes`) wins, and so
    do the point probe, a field that states no length scale (uniform, linear and power-law
    scenes: the probe's default count) and traced inputs. The choice is memoised: the same
    field and heights give the same static node counts, so nothing recompiles.
    """
    if isinstance(probe, PointProbe) or not getattr(probe, "auto_nodes", False):
        return probe
    try:
        resolution = field.resolution
        if resolution is None:
            return probe
        ranges = np.asarray(_focus_ranges(scan, jnp.atleast_1d(jnp.asarray(heights))), np.float64)
    except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
        return probe
    if mount is None or not is_concrete(mount, probe):
        return probe_for_ranges(probe, resolution, ranges, caller=caller)

    if field.spacing_at(np.zeros((0, 3))) is None:  # the same spacing everywhere
        return probe_for_ranges(probe, resolution, ranges, caller=caller)
    # memoised on the arrays' identity, then on the heights' values
    per_heights = _CHOSEN((field, scan, mount, probe), dict)
    key = ranges.tobytes()
    if key not in per_heights:
        per_heights[key] = _graded(field, scan, mount, probe, resolution, ranges, caller)
    return per_heights[key]


@eqx.filter_jit
def _focus_ranges(scan, heights):
    """Focus ranges ``(h, b)`` of `scan`'s beams at `heights`, as `simulate` computes them (one
    compiled call: `probe_for_field` runs on every `simulate` call)."""
    return heights[:, None] / scan.directions()[None, :, 2]


def _graded(field, scan, mount, probe, resolution, ranges, caller):
    """`probe_for_field` with a mount: node counts per height from the spacing along the
    beams' support (see there)."""
    spacing = _support_spacing(field, scan, mount, probe, ranges)
    res = float(resolution)
    if spacing is None:
        return probe_for_ranges(probe, resolution, ranges, caller=caller)
    spacing = np.where(np.isfinite(spacing), np.maximum(spacing, res), res)
    # down to a ladder of quarter octaves above the finest spacing (never coarser than the
    # spacing read): heights on one rung share one node choice
    rung = np.floor(4 * np.log2(spacing / res) + 1e-9)
    if np.all(rung <= 0):
        return probe_for_ranges(probe, resolution, ranges, caller=caller)
    by_rung = {}
    for k in np.unique(rung):
        rows = rung == k
        dx = res * 2.0 ** (k / 4)
        # the finest rung holds no finer content elsewhere: the whole tolerance is its own
        tol = TRANSFER_TOL if k <= 0 else TRANSFER_TOL - 2 * SUPPORT_SHARE
        by_rung[k] = probe_for_ranges(probe, dx, ranges[rows], caller=caller, tol=tol)
    chosen = [by_rung[k] for k in rung]
    keys = [_rule_key(p) for p in chosen]
    if len(set(keys)) == 1:
        return chosen[0]
    probes, index, groups = [], {}, []
    for i, key in enumerate(keys):
        if key not in index:
            index[key] = len(probes)
            probes.append(chosen[i])
        k = index[key]
        if groups and groups[-1][2] == k:
            groups[-1] = (groups[-1][0], i + 1, k)
        else:
            groups.append((i, i + 1, k))
    return GradedProbe(tuple(probes), tuple(groups))


def _rule_key(probe):
    res = float(probe.resolution) if isinstance(probe, CWProbe) else None
    return probe.n_nodes, res


def _support_spacing(field, scan, mount, probe, ranges):
    """Per height ``(h,)``: the largest spacing ``dx`` such that, on every beam (of every
    mount) at that height, at most `SUPPORT_SHARE` of the cut weighting lies where the field
    is finer than ``dx`` (`AbstractField.spacing_at` along the support). None when the field
    reads no spacing at points."""
    loc, dirs = _host_beams(scan, mount)  # (s, 3), (s, b, 3)
    x = np.linspace(-1.0, 1.0, _SUPPORT_SAMPLES)
    half = host_weighting(probe, 0.0, ranges)[1]  # (h, b)
    off = half[..., None] * x  # (h, b, n)
    w = host_weighting(probe, off, ranges)[0]
    w = w * half[..., None]  # equal steps in x: weight per sample is phi * half * dx
    w = w / np.sum(w, axis=-1, keepdims=True)
    pts = (loc[:, None, None, None, :]
           + (ranges[..., None] + off)[None, ..., None] * dirs[:, None, :, None, :])  # (s,h,b,n,3)
    sp = field.spacing_at(pts.reshape(-1, 3))
    if sp is None:
        return None
    sp = np.asarray(sp, np.float64).reshape(pts.shape[:-1])
    w = np.broadcast_to(w, sp.shape)
    order = np.argsort(sp, axis=-1)
    s_sorted = np.take_along_axis(sp, order, axis=-1)
    w_sorted = np.take_along_axis(w, order, axis=-1)
    below = np.cumsum(w_sorted, axis=-1) - w_sorted  # weight strictly finer than each sample
    ok = below <= SUPPORT_SHARE
    # the coarsest spacing whose finer share stays within SUPPORT_SHARE, per beam
    per_beam = np.max(np.where(ok, s_sorted, -np.inf), axis=-1)  # (s, h, b)
    return np.min(per_beam, axis=(0, 2))


def _host_beams(scan, mount):
    """Host float64 lidar locations ``(s, 3)`` and CFD beam directions ``(s, b, 3)`` of one
    mount or a batch."""
    rot, n_body = (np.asarray(a, np.float64) for a in _rotations(scan, mount))
    dirs = np.einsum("sij,bj->sbi", rot.reshape(-1, 3, 3), n_body)
    loc = np.asarray(mount.location, np.float64) + np.asarray(mount.location_lo, np.float64)
    return loc.reshape(-1, 3), dirs


@eqx.filter_jit
def _rotations(scan, mount):
    """Body -> CFD rotations ``(s, 3, 3)`` of one mount or a batch, and the body-frame beams."""
    one = jax.vmap(body_to_cfd_rotation) if mount.batch_shape else body_to_cfd_rotation
    return one(mount), scan.directions()


def pattern_probe(field: AbstractField, pattern, probe: AbstractProbe, caller: str,
                  shared: bool = True):
    """A scanning pattern's probe with its nodes chosen for the field's resolution at its
    gates (`lidarjax.probe.probe_for_ranges`), and the gates' shared-node rule
    (`shared_gate_rule`; None: per-gate nodes, always without `shared`); host choices
    memoised on the inputs' arrays."""
    if isinstance(probe, PointProbe) or not is_concrete(pattern.ranges, probe):
        return probe, None

    def choose():
        chosen = probe
        if getattr(probe, "auto_nodes", False):
            try:
                resolution = field.resolution
            except (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError):
                resolution = None
            chosen = probe_for_ranges(probe, resolution, np.asarray(pattern.ranges, np.float64),
                                      caller=caller)
        return chosen, shared_gate_rule(chosen, pattern.ranges)

    chosen, rule = _CHOSEN((field, pattern.ranges, probe), choose)
    return chosen, rule if shared else None


def gate_nodes(field: AbstractField, pattern, probe: AbstractProbe, *,
               shared_nodes: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """The range-weighting quadrature `lidarjax.simulate_scan` integrates every gate of
    `pattern` (a `lidarjax.scanning.ScanPattern`) with in `field`: host ``(offsets,
    weights)``, each ``(g, q)``, offsets in m from the gate centre along the beam (positive
    away from the lidar), weights summing to 1 per gate (0 for nodes the cut at the lidar
    drops).

    A `lidarjax.PulsedProbe` on equally spaced gates shares its nodes between neighbouring
    gates (`shared_nodes`, the default): each beam is sampled once every ``h`` (at most the
    spacing the probe's own rule needs for the field's resolution, and a whole fraction of
    the gate spacing) and a gate weights the samples within its support by the weighting
    ``phi``. Otherwise, and with ``shared_nodes=False``, every gate has the probe's own
    nodes (`PulsedProbe.nodes`, `CWProbe.nodes`). Both integrate the weighting's transfer
    function within 0.01 up to the field's Nyquist wavenumber. The point probe: one node of
    weight 1 at every gate.
    """
    probe = PointProbe() if probe is None else probe
    if not isinstance(probe, AbstractProbe):
        raise ValueError(f"gate_nodes: `probe` must be a lidarjax probe, got {type(probe).__name__}.")
    ranges = np.asarray(pattern.ranges, np.float64)
    if isinstance(probe, PointProbe):
        return np.zeros((ranges.size, 1)), np.ones((ranges.size, 1))
    probe, rule = pattern_probe(field, pattern, probe, "gate_nodes", shared_nodes)
    return gate_quadrature(probe, ranges, rule)


# ---------------------------------------------------------------------------------------
# points: every point a path samples


def beam_points(field: AbstractField | None, scan, mount: Mount, heights=None,
                probe: AbstractProbe | None = None, *,
                shared_nodes: bool = True) -> Float[np.ndarray, "n 3"]:
    """Every point a path samples along the beams of `scan` from one `mount`, absolute CFD
    metres ``(n, 3)`` (float64, host): what an exact sampler (`lidarjax.io.cellpoint_field`)
    is prepared at.

    **Arguments:**

    - `field`: the field that will be sampled (or the grid a mesh is resampled to): the
      nodes follow its resolution, as `lidarjax.simulate` chooses them (`probe_for_field`
      with the mount; `pattern_probe`). ``None``: `probe` is used as given.
    - `scan`: a profiling `lidarjax.Scan` (then `heights`, m above the lidar) or a scanning
      pattern (`lidarjax.scanning.ScanPattern`; no `heights`: it has its gates).
    - `mount`: one `lidarjax.Mount` (several: call per mount and stack).
    - `probe`: as given to `simulate` / `simulate_scan` (default the point probe).
    - `shared_nodes`: a pattern's shared gate nodes, as `lidarjax.simulate_scan`.

    A profiler: each beam's quadrature nodes (those behind the lidar included: they are
    sampled before the cut gives them no weight), every beam's focus (the probe's limit
    when a cut leaves an even node count none) and the point reference ``h`` above the lidar
    (`simulate_points`). A pattern: every sub-ray's nodes of every gate as `gate_nodes`
    lays them out, and every gate centre (`scan_points`).
    """
    probe = PointProbe() if probe is None else probe
    if not isinstance(mount, Mount) or mount.batch_shape:
        raise ValueError("beam_points: needs one lidarjax.Mount, not a batch; call it per mount.")
    if isinstance(scan, Scan):
        if heights is None:
            raise ValueError("beam_points: a profiling scan needs `heights` (m above the lidar).")
        if field is not None:
            probe = probe_for_field(field, scan, heights, probe, mount=mount, caller="beam_points")
        return simulate_points(scan, mount, heights, probe)
    if not hasattr(scan, "sub_directions"):
        raise ValueError(f"beam_points: `scan` must be a lidarjax.Scan or a scanning pattern "
                         f"(lidarjax.scanning.ScanPattern), got {type(scan).__name__}.")
    if heights is not None:
        raise ValueError("beam_points: a scanning pattern samples its own gates; drop `heights`.")
    if field is None:
        raise ValueError("beam_points: a scanning pattern's nodes follow the field; pass it.")
    return scan_points(field, scan, mount, probe, shared_nodes=shared_nodes)


class ExactPoints:
    """``field -> points``: every point a profiler path samples from one mount
    (`simulate_points`), the probe's nodes chosen for the field by `probe_for_field` *with
    the mount*, exactly as `lidarjax.simulate`, the rotations, `sensitivity`,
    `lidarjax.simulate_series` and `lidarjax.simulate_statistics` choose them: the
    ``exact_at`` of `lidarjax.io.load_field` and `lidarjax.io.load_field_sequence` (a mesh
    loaded with it is exact, the mesh's own cellPoint, at the points those paths sample).
    The probe chosen is kept as `probe` (None until called), so that a caller can show it.

    The one place the profiler paths (`simulate --field`, `build_table`, `simulate_settings`,
    `sensitivity_report`, sequences, `lidarjax series`) prepare their points. A plain
    class, so Dask can ship it.

    **Arguments:** `scan`, `mount` (one, not a batch), `heights` (m above the lidar) and
    `probe` (None: the point probe) as given to `simulate` / `simulate_series`.
    """

    def __init__(self, scan, mount: Mount, heights, probe=None):
        self.scan, self.mount, self.probe_given = scan, mount, probe
        self.heights = np.asarray(heights, np.float64)
        self.probe = None

    def __call__(self, field) -> np.ndarray:
        used = self.probe_given
        if used is not None:
            used = probe_for_field(field, self.scan, jnp.asarray(self.heights), used,
                                   mount=self.mount, caller="exact points")
        self.probe = used
        return simulate_points(self.scan, self.mount, self.heights, used)


class _MeshSource:
    """What `lidarjax.io.load_field` keeps of a mesh it resampled without ``exact_at``: its
    name and ``prepare(points) -> field`` (the grid made exact, the mesh's own cellPoint, at
    `points` or a function of the grid returning them); the last field prepared is reused
    for the same points."""

    def __init__(self, prepare, name: str):
        self.prepare, self.name, self.warned = prepare, name, False
        self.last: tuple[np.ndarray, AbstractField] | None = None


_MESH_GRIDS: dict[int, tuple[weakref.ref, _MeshSource]] = {}


def register_mesh_grid(grid: AbstractField, prepare, name: str) -> None:
    """Remember that `grid` was resampled from the mesh `name` (held as long as `grid` is):
    `lidarjax.simulate` then samples ``prepare(points)``, the grid exact (the mesh's own
    cellPoint) at the points it samples, wherever they are known on the host (a fixed
    mount), and warns once in one line where they are not (`exact_by_default`)."""
    key = id(grid)
    # The callback holds the registry itself: at interpreter exit a grid may outlive the
    # module's globals (then None), and its callback must still find the dict.
    _MESH_GRIDS[key] = (weakref.ref(grid, lambda _, k=key, grids=_MESH_GRIDS: grids.pop(k, None)),
                        _MeshSource(prepare, name))


def exact_by_default(field, scan, mount: Mount, heights, probe, caller: str, *,
                     moving: bool = False):
    """`field` as `simulate` samples it: a grid `lidarjax.io.load_field` resampled from a
    mesh without ``exact_at`` is made exact at the points `scan` samples from `mount`
    (`ExactPoints`, for a scanning pattern `scan_points`: the nodes `simulate` chooses)
    where they are known on the host (one concrete mount); elsewhere the grid, with a
    one-line warning (once per field) naming its local spacing and the fix. Any other field
    is returned as it is. `moving`: the lidar moves (a platform motion): not prepared."""
    entry = _MESH_GRIDS.get(id(field))
    if entry is None or entry[0]() is not field:
        return field
    src = entry[1]
    if moving or not (isinstance(mount, Mount) and not mount.batch_shape
                      and is_concrete(mount, heights) and is_concrete(field)):
        if not src.warned:
            src.warned = True
            graded_warning(caller, field, mount, heights, src.name,
                           "a moving lidar's points are not known in advance" if moving else
                           "the points of a batch or traced mount are not known on the host",
                           "prepare them with load_field(..., exact_at=lidarjax.ExactPoints("
                           "scan, mount, heights, probe)) per mount, or exact_at=False to "
                           "accept the grid")
        return field
    if heights is None:  # a scanning pattern: its own gates
        points = scan_points(field, scan, mount, probe)
    else:
        points = ExactPoints(scan, mount, heights, probe)(field)
    if src.last is None or not np.array_equal(src.last[0], points):
        src.last = (points, src.prepare(points))
    return src.last[1]


def graded_warning(caller: str, field, mount: Mount, heights, what: str, why: str,
                   fix: str) -> None:
    """One-line `UserWarning` of `caller`: `why`, the run samples the graded grid resampled
    from the mesh `what` (its local spacing directly above the lidar at the lowest and the
    highest height, m) instead of the mesh's own cellPoint values; `fix`."""
    warnings.warn(f"{caller}: {why}, so it samples the graded grid of {what}"
                  f"{_spacing_text(field, mount, heights)}, not the mesh's own cellPoint values "
                  f"(next to a graded ground typically 0.1 m/s off OpenFOAM's probes); {fix}",
                  UserWarning, stacklevel=3)


def _spacing_text(field, mount: Mount, heights) -> str:
    """`` (local spacing 1.25 m at 10 m, 5 m at 60 m above the lidar)`` for the warning (the
    grid's finest spacing where the lidar's place is not known on the host)."""
    try:
        loc = (np.asarray(mount.location, np.float64).reshape(-1, 3)[0]
               + np.asarray(mount.location_lo, np.float64).reshape(-1, 3)[0])
        h = np.sort(np.atleast_1d(np.asarray(heights, np.float64)).reshape(-1))
        s = field.spacing_at(loc + h[:, None] * np.array([0.0, 0.0, 1.0]))
        s = np.full(h.shape, field.resolution, np.float64) if s is None else np.asarray(s)
    except (TypeError, ValueError, AttributeError, jax.errors.ConcretizationTypeError):
        s = None  # a traced mount: where it stands is not known on the host
    if s is None or not np.isfinite(s).any():
        r = getattr(field, "resolution", None)
        return "" if r is None else f" (finest spacing {r:.3g} m)"
    ends = [(s[k], h[k]) for k in sorted({0, h.size - 1}) if np.isfinite(s[k])]
    return " (local spacing " + ", ".join(
        f"{a:.3g} m at {b:g} m" for a, b in ends) + " above the lidar)"


def simulate_points(
    scan: Scan,
    mount: Mount,
    heights: Float[ArrayLike, " h"],
    probe: AbstractProbe | None = None,
) -> Float[np.ndarray, "n 3"]:
    """Every point `lidarjax.simulate` samples for one mount, absolute CFD metres `(n, 3)`
    (float64 on the host): `beam_points` for a profiling scan with the probe as given.

    **Arguments:** `scan`, `mount` (one, not a batch), `heights` (m above the lidar) and
    `probe` exactly as `simulate` uses it *after* its node choice: pass
    ``lidarjax.probe_for_field(field, scan, heights, probe, mount=mount)`` for a probe with
    automatic nodes (or call ``beam_points(field, scan, mount, heights, probe)``). The
    geometry is `profile_geometry` and the nodes the probe's, computed in one compiled call
    in the working dtype, so a `lidarjax.io.CellPointField` prepared at these points matches
    `simulate`'s own queries to rounding.
    """
    if not isinstance(scan, Scan) or not isinstance(mount, Mount) or mount.batch_shape:
        raise ValueError("simulate_points: needs a lidarjax.Scan and one lidarjax.Mount (not a batch)")
    probe = PointProbe() if probe is None else probe
    h = np.atleast_1d(np.asarray(heights, np.float64))
    if h.ndim != 1 or h.size == 0 or not np.all(np.isfinite(h)) or np.any(h <= 0):
        raise ValueError(f"simulate_points: heights must be positive metres, got {h.tolist()}")
    local = np.asarray(_local_points(scan, mount, jnp.asarray(h), probe), np.float64)
    loc = np.asarray(mount.location, np.float64) + np.asarray(mount.location_lo, np.float64)
    return loc + local.reshape(-1, 3)


@eqx.filter_jit
def _local_points(scan, mount, heights, probe):
    """The points of `simulate_points` relative to the lidar, as `lidarjax.simulate` forms them."""
    with jax.default_matmul_precision("highest"):
        n_cfd, ranges = profile_geometry(scan, mount, heights)
        dtype = heights.dtype
        out = [ranges[..., None] * n_cfd, heights[:, None] * jnp.array([0.0, 0.0, 1.0], dtype)]
        if not isinstance(probe, PointProbe):
            offsets, _ = probe.nodes(ranges)
            offsets = jnp.broadcast_to(offsets.astype(dtype), ranges.shape + offsets.shape[-1:])
            node_ranges = ranges[..., None] + offsets
            out.append(node_ranges[..., None] * n_cfd[:, None, :])
        return jnp.concatenate([o.reshape(-1, 3) for o in out])


def scan_points(field: AbstractField, pattern, mount: Mount,
                probe: AbstractProbe | None = None, *, shared_nodes: bool = True) -> np.ndarray:
    """Every point `lidarjax.simulate_scan` samples for `pattern` from one `mount` in
    `field`, absolute CFD metres ``(n, 3)`` (float64, host): `beam_points` for a scanning
    pattern. Each sub-ray's nodes of every gate as `gate_nodes` lays them out (those the cut
    at the lidar drops included: they are sampled, then given no weight), and every gate
    centre. Prepare a mesh's exact interpolation at them
    (`lidarjax.io.load_field(..., exact_at=lambda grid: scan_points(grid, ...))`): the nodes
    depend on the field's resolution, so pass the field that will be simulated, or its grid.
    """
    probe = PointProbe() if probe is None else probe
    if not isinstance(mount, Mount) or mount.batch_shape:
        raise ValueError("scan_points: needs one lidarjax.Mount, not a batch; call it per mount.")
    ranges = np.asarray(pattern.ranges, np.float64)
    offsets = gate_nodes(field, pattern, probe, shared_nodes=shared_nodes)[0]
    node_r = np.concatenate([ranges[:, None] + offsets, ranges[:, None]], axis=1)
    loc, n = pattern_geometry(pattern, mount)
    return (loc + np.unique(node_r)[:, None, None] * n[None]).reshape(-1, 3)


# ---------------------------------------------------------------------------------------
# LOS: the probe quadrature along beams


def beam_los(field, origin_local, directions, ranges, probe, los=None):
    """LOS ``(h, b)`` for focus ranges ``(h, b)`` along CFD beam `directions` ``(b, 3)``
    from the lidar at `origin_local` (m, relative to the field's origin), and ``(h, b)``
    booleans: the probe's symmetric cut at the lidar dropped more than its ``tail`` of
    weight (None for the point probe, which compiles no quadrature at all). A `GradedProbe`
    integrates each group of heights (rows of `ranges`) with its own node count.

    A beam is NaN when its focus (point probe) or any quadrature node ahead of the lidar is
    outside the field or in a solid. NaN node values never meet arithmetic on the inputs
    (they are masked before the weighted sum and put back last), so the gradients of the
    finite results, and of a loss that masks the NaN ones, stay finite.

    `los`: optional ``los(points, directions)`` used instead of ``field.los_local`` (a time
    series samples prepared fixed points at many times: its result may carry leading time
    axes, broadcast against ``points.shape[:-1]``). With a `GradedProbe` it is called per
    group of heights as ``los(points, directions, rows=slice)``, `rows` the group's heights
    (so that it can pick what it holds per height, e.g. each LOS's time)."""
    if not isinstance(probe, GradedProbe):
        return _beam_los(field, origin_local, directions, ranges, probe, los)
    if ranges.ndim != 2 or ranges.shape[0] != probe.n_heights:
        raise ValueError(f"beam_los: a GradedProbe holds node counts for {probe.n_heights} "
                         f"heights, got focus ranges {ranges.shape}; use its `finest` probe "
                         f"there.")
    parts = [_beam_los(field, origin_local, directions, ranges[rows], p,
                       None if los is None else functools.partial(los, rows=rows))
             for rows, p in probe.rows()]
    return (jnp.concatenate([p[0] for p in parts], axis=-2),
            jnp.concatenate([p[1] for p in parts], axis=0))



def _beam_los(field, origin_local, directions, ranges, probe, los=None):
    """`beam_los` with one node count for every height."""
    los_fn = field.los_local if los is None else los
    if isinstance(probe, PointProbe):
        pts = origin_local + ranges[..., None] * directions
        return los_fn(pts, directions), None
    offsets, weights = probe.nodes(ranges)  # (h, b, q) or broadcastable
    offsets = jnp.broadcast_to(offsets.astype(ranges.dtype), ranges.shape + offsets.shape[-1:])
    weights = jnp.broadcast_to(weights.astype(ranges.dtype), offsets.shape)
    node_ranges = ranges[..., None] + offsets
    pts = origin_local + node_ranges[..., None] * directions[:, None, :]
    los_q = los_fn(pts, directions[:, None, :])
    # no light returns from behind the lidar: cut the probe symmetrically at the lidar
    # (|offset| < range, so it stays centred on the focus) and renormalise
    ahead, kept, total = _cut(offsets, weights, ranges)
    los = _probe_mean(los_q, jnp.broadcast_to(kept, los_q.shape), jnp.broadcast_to(ahead, los_q.shape))
    if offsets.shape[-1] % 2 == 0:
        # Symmetric nodes of an odd count include the focus (offset 0), which is always
        # kept. An even count has none: when the cut keeps no node (focus range below the
        # innermost offset), the probe's limit is the focus itself.
        focus = los_fn(origin_local + ranges[..., None] * directions, directions)
        los = jnp.where(total <= 0, focus, los)
    return los, _truncated(probe, total)


def _cut(offsets, weights, ranges):
    """The probe's symmetric cut at the lidar for nodes at `offsets` ``(..., q)`` around
    focus ranges ``(...)``: ``(ahead, kept weights, kept total)``, nodes ahead of the lidar
    (``|offset| < range``) and their weights."""
    ahead = jnp.abs(offsets) < ranges[..., None]
    kept = jnp.where(ahead, weights, 0)
    return ahead, kept, jnp.sum(kept, axis=-1)


def _truncated(probe, total):
    """The cut dropped more than the probe's `tail` of its weighting (`total`: the kept
    weight of the probe's own rule)."""
    return (1 - total) > jnp.asarray(getattr(probe, "tail", 0.0)).astype(total.dtype)


def shared_gate_rule(probe, ranges) -> tuple[int, int] | None:
    """Host choice of the shared-node rule for equally spaced range gates (`gates_los`):
    ``(m, J)`` with ``m`` nodes per gate spacing and ``2 J + 1`` nodes per gate, or ``None``
    where every gate keeps its own nodes (`beam_los`).

    The rule samples each beam once, every ``h = spacing / m`` from the first gate, and
    weights node ``j`` of a gate (``j = -J..J``, offset ``j h`` from its centre) by
    ``phi(j h)``; neighbouring gates share their nodes. ``h`` is at most the spacing of the
    probe's own rule (``2 support / n_nodes``, chosen for the field's resolution), so its
    error, the weighting's transfer function at the alias ``2 pi / h - k``, stays within the
    same tolerance, and ``J h`` covers the support. It applies to a `PulsedProbe` (a
    weighting independent of range) at 2 or more gates equally spaced to 1e-9 (host numbers),
    when it samples fewer points than per-gate nodes do."""
    if not isinstance(probe, PulsedProbe) or not is_concrete(probe, ranges):
        return None
    r = np.asarray(ranges, np.float64).reshape(-1)
    if r.size < 2 or not np.all(np.isfinite(r)):
        return None
    d = np.diff(r)
    if not (r[0] >= 0 and d[0] > 0 and np.allclose(d, d[0], rtol=1e-9, atol=0.0)):
        return None
    support = float(probe.support())
    m = max(1, math.ceil(d[0] * probe.n_nodes / (2 * support) - 1e-9))
    half = int(math.floor(support * m / d[0] + 1e-9))
    if half < 1 or m >= 2 * half + 1:
        return None
    return m, half


def gate_quadrature(probe, ranges, rule):
    """Host ``(offsets, weights)`` ``(g, q)`` of every gate at `ranges` ``(g,)`` as the
    simulator integrates them: the shared-node `rule` ``(m, J)`` (`shared_gate_rule`) or,
    with ``None``, the probe's own nodes per gate. Nodes the cut at the lidar drops have
    weight 0; each gate's weights sum to 1."""
    r = np.asarray(ranges, np.float64).reshape(-1)
    if rule is None:
        offsets, weights = host_nodes(probe, r)
    else:
        m, half = rule
        h = (r[1] - r[0]) / m
        offsets = np.broadcast_to((np.arange(2 * half + 1) - half) * h, (r.size, 2 * half + 1))
        weights = host_weighting(probe, offsets, r[:, None])[0]
    weights = np.where(np.abs(offsets) < r[:, None], weights, 0.0)
    total = weights.sum(axis=-1, keepdims=True)
    return np.array(offsets), weights / np.where(total > 0, total, 1.0)


def gates_los(field, origin_local, directions, ranges, probe, rule, los=None, windows=None):
    """`beam_los` for equally spaced gates ``(g,)`` with the shared-node rule ``(m, J)`` of
    `shared_gate_rule`: LOS ``(g, b)`` and the truncation flags ``(g, 1)``. `los` (as in
    `beam_los`) is called with points ``(b, L, 3)`` and directions ``(b, 1, 3)``: a leading
    time axis of its result broadcasts against ``(b, L)``.

    The beam is sampled at ``L = (g - 1) m + 2 J + 1`` ranges ``r_0 + (l - J) h``; gate ``i``
    takes nodes ``i m .. i m + 2 J``. The lidar cut, NaN and derivative rules are those of
    `beam_los` (nodes ``|j h| >= r_i`` are dropped, the weights renormalised; the flag
    compares the kept weight of the weighting itself with `tail`). Every number stays
    dynamic: the gates' first range and spacing, and the probe's pulse and gate length."""
    m, half = rule
    los_fn = field.los_local if los is None else los
    g = ranges.shape[0]
    dtype = ranges.dtype
    h = (ranges[1] - ranges[0]) / m
    n_fine = (g - 1) * m + 2 * half + 1
    fine = ranges[0] + (jnp.arange(n_fine, dtype=dtype) - half) * h  # (L,)
    # beam-major (b, L): consecutive samples lie along one beam, so the field's cells they
    # read are neighbours in memory
    pts = origin_local + fine[None, :, None] * directions[:, None, :]  # (b, L, 3)
    fine_los = los_fn(pts, directions[:, None, :])  # (..., b, L)
    # each gate's window. On a CPU, a strided convolution (`_window_mean`): the compiler
    # fuses the field's interpolation into an index gather of the windows (or into strided
    # slices), computing every sample once per gate that holds it, 2 J / m times, in an
    # order that leaps between beams; a convolution reads the samples once, computed beam by
    # beam (the 10-minute PPI series of benchmarks/scanning.py 3x faster). The near gates,
    # whose nodes the cut can drop, sample their own nodes, so the convolution stays the
    # samples' one reader. On an accelerator, one index gather (as measured on the H100).
    offsets = (jnp.arange(2 * half + 1, dtype=dtype) - half) * h  # (q,)
    phi = probe.weight(offsets).astype(dtype)  # (q,)
    ahead, kept, _ = _cut(offsets, phi, ranges)  # (g, q) each
    if windows is None:
        windows = "gather" if is_accelerator() else "convolution"
    # gates beyond ``J h`` keep every node (``r_i >= i m h``, so gates ``i > J / m``); only
    # the first ``J // m + 1`` can lose nodes to the cut at the lidar
    k0 = g if windows == "gather" else min(g, half // m + 1)
    if k0 == g:
        window = np.arange(g)[:, None] * m + np.arange(2 * half + 1)[None, :]  # (g, q)
        los_q = fine_los[..., window]  # (..., b, g, q)
    else:  # the near gates sample their own nodes: the convolution is the samples' one reader
        near = (ranges[:k0, None] + offsets).reshape(-1)  # (k0 q,)
        los_q = los_fn(origin_local + near[None, :, None] * directions[:, None, :],
                       directions[:, None, :])
        los_q = los_q.reshape(los_q.shape[:-1] + (k0, 2 * half + 1))  # (..., b, k0, q)
    shape = los_q.shape
    los = _probe_mean(los_q, jnp.broadcast_to(kept[:k0], shape), jnp.broadcast_to(ahead[:k0], shape))
    if k0 < g:
        los = jnp.concatenate([los, _window_mean(fine_los, phi, m)[..., k0:]], axis=-1)
    los = jnp.swapaxes(los, -1, -2)  # (..., g, b)
    # the flag: the weighting's own kept weight at each gate, as `beam_los` computes it
    off_p, w_p = probe.nodes(ranges)
    total = _cut(off_p.astype(dtype), w_p.astype(dtype), ranges)[2]
    return los, _truncated(probe, total)[:, None]


@functools.partial(jax.custom_jvp, nondiff_argnums=(2,))
def _window_mean(samples, phi, m: int):
    """Weighted means of equal windows along the last axis: ``(..., L)`` samples ->
    ``(..., g)``, ``g = (L - q) / m + 1``, window ``i`` being samples ``i m .. i m + q - 1``
    weighted by `phi` ``(q,)``: ``sum_j phi_j s[i m + j] / sum_j phi_j``. NaN where a sample
    of the window is NaN (as `_probe_mean` with every node kept).

    One strided convolution, so the samples are an operand the compiler computes once
    (it copies cheap producers into the consumers of an index gather). The derivative
    (below) zeroes NaN samples before they meet a tangent, so a loss that masks NaN gates
    gets finite gradients for the weights, as `_probe_mean`'s does."""
    return _correlate(samples, phi, m) / jnp.sum(phi)


def _correlate(samples, phi, m):
    lead = samples.shape[:-1]
    out = jax.lax.conv_general_dilated(samples.reshape(-1, 1, samples.shape[-1]),
                                       phi.astype(samples.dtype)[None, None, :], (m,), "VALID",
                                       precision=jax.lax.Precision.HIGHEST)
    return out.reshape(lead + out.shape[-1:])


@_window_mean.defjvp
def _window_mean_jvp(m, primals, tangents):
    samples, phi = primals
    d_samples, d_phi = tangents
    mean = _window_mean(samples, phi, m)
    bad = jnp.isnan(samples)
    safe = jnp.where(bad, 0, samples)
    d_mean = (_correlate(jnp.where(bad, 0, d_samples), phi, m) + _correlate(safe, d_phi, m)
              - jnp.where(jnp.isnan(mean), 0, mean) * jnp.sum(d_phi)) / jnp.sum(phi)
    return mean, jnp.where(jnp.isnan(mean), 0, d_mean)


@jax.custom_jvp
def _probe_mean(los_q, kept, ahead):
    """``sum(kept * los_q) / sum(kept)`` over the nodes ahead of the lidar (last axis), 0 when
    none is kept; NaN when a node ahead is NaN (outside the field or in a solid).

    NaN node values flow through this plain form, which keeps the field's gather fused with
    the weighted sum (masking them first costs 5-7x in throughput). The derivative (below) is
    written out with the NaN beams masked, so `0 * NaN` cannot reach the weights (probe
    parameters, heights) even for a loss that masks the NaN LOS out; it is zero there."""
    total = jnp.sum(kept, axis=-1)
    return jnp.sum(jnp.where(ahead, kept * los_q, 0), axis=-1) / jnp.where(total > 0, total, 1)


@_probe_mean.defjvp
def _probe_mean_jvp(primals, tangents):
    los_q, kept, ahead = primals
    d_los, d_kept, _ = tangents
    mean = _probe_mean(los_q, kept, ahead)
    ok = jnp.isfinite(mean)
    use = ahead & ok[..., None]
    total = jnp.sum(kept, axis=-1)
    # NaN node values are zeroed before they multiply a tangent: the transpose (reverse mode)
    # would otherwise multiply a zero cotangent by them (range-dependent weights)
    los_safe = jnp.where(use, los_q, 0)
    d_mean = jnp.sum(jnp.where(use, kept * d_los + d_kept * los_safe, 0), axis=-1)
    d_mean = d_mean - jnp.where(ok, mean, 0) * jnp.sum(d_kept, axis=-1)
    return mean, d_mean / jnp.where(total > 0, total, 1)
