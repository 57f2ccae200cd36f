"""The seed UDF's workflow on top of `simulate`: settings.dat in, seed output files out.

`simulate_settings` runs every platform rotation (beta) of a `Settings` in compiled batches
when the CFD runs share a grid (one trace, ``jax.vmap`` over the runs and one batched
`Mount`, from `settings_mount`), and
`seed_columns` turns a `Simulation` into the seed's 21 output columns.
"""

from __future__ import annotations

import inspect
import time
from collections.abc import Callable, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._backend import default_batch, positive_size
from .._precision import host_array
from .._util import import_optional
from ..angles import horizontal_speed, seed_azimuth
from ..batch import simulate_rotations, stack_fields
from ..beam import ExactPoints
from ..field import GridField, IndexedPoints
from ..footprint import scan_bounds
from ..forward import Simulation, beam_gradient, probe_for_field, simulate
from ..io.settings import Settings
from ..mount import Mount
from ..progress import AbstractProgress, LineProgress, progress_meter
from ..response import ProfileTable, ResponseTable, TableRuns

__all__ = ["seed_columns", "simulate_settings", "build_table", "table_region", "table_runs",
           "settings_mount", "settings_mounts", "settings_probes", "SEED_U_REF", "ExactPoints",
           "load_exact"]

#: The free stream hard-coded in the seed UDF (its CFD inlet), CFD frame, m/s.
SEED_U_REF = (-15.0, 0.0, 0.0)


def seed_columns(sim: Simulation) -> dict[str, np.ndarray]:
    """The seed's 21 output columns for one `Simulation` (heights ``(h,)``).

    Speeds in m/s, ``Th_lidar`` / ``th_point`` in the seed's azimuth (flow heading clockwise
    from ``+x``; see `lidarjax.seed_azimuth`), factors as in `lidarjax.corrections`. Factors
    whose reference was not simulated are NaN.
    """
    h = np.asarray(sim.heights)
    nan = np.full(h.shape, np.nan)
    L = sim.lidar_velocity
    P = sim.point_velocity if sim.point_velocity is not None else jnp.full(L.shape, jnp.nan)
    cols = {
        "h": h,
        "U_mag_lidar": horizontal_speed(L), "U_lidar": L[:, 0], "V_lidar": L[:, 1],
        "W_lidar": L[:, 2], "Th_lidar": seed_azimuth(L),
        "U_mag_point": horizontal_speed(P), "U_point": P[:, 0], "V_point": P[:, 1],
        "W_point": P[:, 2], "th_point": seed_azimuth(P),
    }
    for name in ("cff_u", "cff_v", "cff_w", "cff_U", "cff_th",
                 "cfp_u", "cfp_v", "cfp_w", "cfp_U", "cfp_th"):
        value = getattr(sim, name)
        cols[name] = nan if value is None else value
    return {k: np.asarray(v, dtype=np.float64) for k, v in cols.items()}


def settings_mount(settings: Settings, betas: Sequence[float], *, pitch: float = 0.0,
                   roll: float = 0.0) -> Mount:
    """Every platform rotation of `betas` (degrees) as one batched `Mount` (location
    ``(s, 3)`` from the settings' row for each beta, angles ``(s,)``): the settings' gamma,
    psi and epsilon, with the installation's `pitch` and `roll` (degrees). Built in one
    call, whatever the number of rotations; ``mount[k]`` is the mount of ``betas[k]``."""
    betas = np.asarray([float(b) for b in betas], np.float64)
    if betas.size == 0:
        raise ValueError("settings_mount: `betas` is empty; give at least one platform rotation.")
    locations = np.stack([np.asarray(settings.location(b), np.float64) for b in betas])
    return Mount(locations, beta=betas, gamma=settings.gamma, psi=settings.psi,
                 epsilon=settings.epsilon, pitch=pitch, roll=roll)


def settings_mounts(settings: Settings, betas: Sequence[float], *, pitch: float = 0.0,
                    roll: float = 0.0) -> list[Mount]:
    """The `Mount` of each platform rotation, as a list: the settings' location row for that
    beta and its gamma, psi and epsilon, with the installation's `pitch` and `roll`
    (degrees). `settings_mount` gives the same as one batched `Mount`."""
    return [Mount(settings.location(b), beta=b, gamma=settings.gamma, psi=settings.psi,
                  epsilon=settings.epsilon, pitch=pitch, roll=roll) for b in betas]


def _takes_exact_at(load) -> bool:
    try:
        return "exact_at" in inspect.signature(load).parameters
    except (TypeError, ValueError):
        return False


def load_exact(load, key, points: ExactPoints):
    """``load(key)``, made exact at `points` where the loader takes an ``exact_at`` keyword (a
    mesh read by `lidarjax.io.load_field` then comes back as a `lidarjax.io.CellPointField`);
    any other loader (a grid, an analytic scene) is called as it is."""
    return load(key, exact_at=points) if _takes_exact_at(load) else load(key)


def simulate_settings(
    settings: Settings,
    betas: Sequence[float],
    field_for_beta: Callable[[float], GridField],
    scan,
    *,
    u_ref=SEED_U_REF,
    probe=None,
    pitch: float = 0.0,
    roll: float = 0.0,
    batch_size: int | None = None,
) -> dict[float, Simulation]:
    """Simulate the lidar of `settings` for each platform rotation in `betas`.

    **Arguments:**

    - `settings`: a `lidarjax.io.Settings` (heights ``j * height / nh``, gamma, psi,
      epsilon and one location per beta).
    - `betas`: platform rotations (degrees) to run; each needs a location row.
    - `field_for_beta`: loads the CFD run of one beta (e.g. ``lidarjax.io.load_field``). If
      it takes an ``exact_at`` keyword it is given that rotation's `ExactPoints` (a mesh is
      then exact, its own cellPoint, at every point the rotation samples; `load_exact`).
    - `scan`: the `lidarjax.Scan`.
    - `u_ref`: free-stream vector in the CFD frame (m/s); default the seed UDF's.
    - `probe`: probe volume (default point).
    - `pitch`, `roll`: the installation's tilt in degrees (`lidarjax.Mount`), default level.
    - `batch_size`: runs stacked and simulated together (`simulate_rotations` with one
      batched `Mount`); None (default) chooses per backend and the runs' size
      (`lidarjax._backend.default_batch`): as many as fit in an eighth of the available
      memory on a CPU (a quarter of the free device memory on a GPU), all of them for
      ordinary grids. The last batch is padded with its last run, so every batch shares one
      compilation.

    **Returns:** ``{beta: Simulation}``. Runs on one grid are simulated in compiled,
    vmapped batches; otherwise one call per run (one compilation per distinct grid shape).
    """
    runs = _SettingsRuns(settings, betas, field_for_beta, scan, probe, pitch, roll, batch_size,
                         "simulate_settings")
    out: dict[float, Simulation] = {}
    for idx, stacked in runs.batches:
        if stacked is None:
            for k in idx:
                out[runs.betas[k]] = simulate(runs.fields[k], scan, runs.mount[k], runs.heights,
                                              u_ref=u_ref, probe=probe)
            continue
        batch = simulate_rotations(stacked, scan, runs.batch_mount(idx), runs.heights,
                                   u_refs=u_ref, probe=probe)
        # split on the host and put back: indexing each device leaf compiles a program per
        # leaf shape, and so does jnp.asarray of a host array (`host_array` does not)
        host = jax.device_get(batch)
        for j, k in enumerate(idx):
            out[runs.betas[k]] = host_array(jax.tree_util.tree_map(lambda a, j=j: a[j], host))
    return out


def settings_probes(
    settings: Settings,
    betas: Sequence[float],
    field_for_beta: Callable[[float], GridField],
    scan,
    probe,
    *,
    heights=None,
    pitch: float = 0.0,
    roll: float = 0.0,
    batch_size: int | None = None,
) -> dict[float, object]:
    """The probe, its quadrature nodes chosen, that `simulate_settings` samples each platform
    rotation with (same arguments): ``{beta: probe}``.

    The runs are loaded and batched exactly as `simulate_settings` loads and batches them, and
    each is given `probe_for_field` as `simulate` calls it: a mesh made exact at its
    rotation's own points is simulated per rotation (its own node counts per height, from
    the spacing along its own beams), runs stacked on one grid share the batch's choice.
    Rotations may therefore differ in their node counts. `heights` (m above the lidar)
    replaces the settings' ``j * height / nh`` (the choice is per height).
    `lidarjax monitor-points --field` writes the nodes of these probes
    (`lidarjax.monitor_points` takes one per mount).
    """
    runs = _SettingsRuns(settings, betas, field_for_beta, scan, probe, pitch, roll, batch_size,
                         "settings_probes", heights)
    out = {}
    for idx, stacked in runs.batches:
        if stacked is None:
            for k in idx:
                out[runs.betas[k]] = probe_for_field(runs.fields[k], scan, runs.heights, probe,
                                                     mount=runs.mount[k], caller="simulate")
            continue
        used = probe_for_field(stacked, scan, runs.heights, probe, mount=runs.batch_mount(idx),
                               caller="simulate_rotations")
        out.update({runs.betas[k]: used for k in idx})
    return out


class _SettingsRuns:
    """`simulate_settings`' runs and batches (shared with `settings_probes`, so both see
    the same batches): `betas`, the batched `mount`, `heights`, `fields` (each run loaded,
    made exact at its rotation's points where the loader takes ``exact_at``) and `batches`,
    ``[(run indices, stacked field or None: one call per run), ...]``."""

    def __init__(self, settings, betas, field_for_beta, scan, probe, pitch, roll, batch_size,
                 caller, heights=None):
        self.betas = [float(b) for b in betas]
        if batch_size is not None:
            batch_size = positive_size(batch_size, caller, "batch_size")
        self.mount = mount = settings_mount(settings, self.betas, pitch=pitch, roll=roll)
        self.heights = jnp.asarray(settings.heights() if heights is None else heights)
        # a mesh read by a loader that takes `exact_at` is exact at each rotation's own points
        self.fields = fields = [
            load_exact(field_for_beta, b, ExactPoints(scan, mount[k], self.heights, probe))
            for k, b in enumerate(self.betas)]
        n = len(self.betas)
        if batch_size is None:  # the stacked copy and the vmapped temporaries of one run
            per_run = 2 * getattr(fields[0], "nbytes", 0) + 1
            batch_size = default_batch("rotations", per_run, n)
        self.size = size = min(int(batch_size), n)
        self.batches = []
        for i in range(0, n, size):  # the last batch padded with its last run: one compilation
            idx = np.minimum(np.arange(i, i + size), n - 1)
            try:
                # a mesh made exact at each rotation's own points is simulated per rotation: a
                # batch chooses one node count per height for all its mounts, which need not
                # be each rotation's own (the points prepared)
                exact = any(isinstance(fields[k], IndexedPoints) for k in idx)
                stacked = stack_fields([fields[k] for k in idx]) if size > 1 and not exact else None
            except ValueError:  # runs on different grids: one call (and compilation) per grid
                stacked = None
            self.batches.append((range(i, min(i + size, n)), stacked))

    def batch_mount(self, runs: range):
        """The batched `Mount` of a stacked batch (padded with its last run, as its field)."""
        if self.size == len(self.betas):
            return self.mount
        return self.mount[np.minimum(np.arange(runs.start, runs.start + self.size),
                                     len(self.betas) - 1)]


def build_table(
    settings: Settings,
    betas: Sequence[float],
    field_for_beta: Callable[[float], GridField],
    scan,
    *,
    u_ref=SEED_U_REF,
    probe=None,
    pitch: float = 0.0,
    roll: float = 0.0,
    client=None,
    progress: bool | AbstractProgress = False,
    parameter: tuple[str, Sequence[float]] | None = None,
    profile=None,
):
    """A `lidarjax.ResponseTable` from the CFD runs of a seed settings file.

    Each platform rotation ``beta`` is one inflow direction; the table's directions are the
    free streams' meteorological directions in the north frame. The table carries the
    velocity gradient along the beams (`lidarjax.beam_gradient`, taken while each run is
    loaded) for `lidarjax.calibrate`. Returns ``(table, sims)``.

    Runs are loaded **one at a time**: each `GridField` returned by `field_for_beta` is cut
    at once to `scan_bounds` of all mounts (with the probe; `GridField.crop`, bit-exact),
    simulated, and dropped, so the peak memory is about one run whatever their number.
    `field_for_beta` may load only that region itself (``lidarjax.io.load_field(path,
    region=...)``, with `table_region` giving it); any other `AbstractField` (an analytic
    scene) is used as it is. A loader that takes an ``exact_at`` keyword (as
    `lidarjax.io.load_field` does) is given the points of that run's mount (`ExactPoints`): a
    mesh (OpenFOAM case, VTK file) then answers every point the run samples with its own
    cellPoint interpolation, what OpenFOAM's `probes` report, and the graded grid serves no
    point of the table.

    **Arguments** (besides those of `simulate_settings`):

    - `client`: a ``dask.distributed.Client``; runs are then read and simulated in parallel
      on its workers (`field_for_beta` is shipped to them, so it must be picklable by
      cloudpickle and read files the workers can see). The workers must use the caller's
      ``jax_enable_x64`` setting (checked: the command line sets it on them). The table is
      identical to the serial one.
    - `pitch`, `roll`: the installation's tilt in degrees (`lidarjax.Mount`), default level.
    - `progress`: ``True``: one line per finished run on stderr (run, beta, grid before and
      after the crop, seconds; `lidarjax.progress.LineProgress`), or a `lidarjax.progress`
      meter.
    - `parameter`: ``(name, values)`` for runs over directions x one inflow-profile
      parameter (e.g. ``("alpha", [0.0, 0.1, 0.2])``): `field_for_beta` then takes
      ``(beta, value)``, each run's `u_ref` is its free stream at the profile's reference
      height, and the result is a `lidarjax.ProfileTable` (responses divided by `profile`,
      a `lidarjax.AbstractProfile`, default `lidarjax.UniformProfile`) with sims keyed
      ``(beta, value)``.
    """
    if parameter is not None:
        name, values = parameter
        tables, all_sims = [], {}
        for v in [float(x) for x in values]:
            t, s = build_table(settings, betas, _AtValue(field_for_beta, v), scan, u_ref=u_ref,
                               probe=probe, pitch=pitch, roll=roll, client=client,
                               progress=progress)
            tables.append(t)
            all_sims.update({(b, v): sim for b, sim in s.items()})
        return ProfileTable(name, [float(x) for x in values], tables, profile=profile,
                            per_reference_speed=True), all_sims

    betas = [float(b) for b in betas]
    mounts = list(settings_mount(settings, betas, pitch=pitch, roll=roll))  # one per run
    heights = np.asarray(settings.heights())
    lo, hi = table_region(settings, betas, scan, probe=probe, pitch=pitch, roll=roll)
    u_ref = np.asarray(u_ref, np.float64)
    tasks = [(b, m) for b, m in zip(betas, mounts, strict=True)]
    run = _TableRun(field_for_beta, scan, heights, u_ref, probe, lo, hi)
    sims: dict[float, Simulation] = {}
    gradients: dict[float, np.ndarray] = {}

    meter = progress_meter(progress, LineProgress)
    bar = meter.start(len(betas), "table", unit="run")

    def report(k, result):
        b, sim, info = result
        sims[b] = sim
        gradients[b] = info["gradient"]
        meter.update(bar, k, f"beta {b:g}: grid {info['shape']} -> crop {info['crop']} in "
                             f"{info['seconds']:.1f} s")

    if client is None:
        for k, task in enumerate(tasks, 1):
            report(k, run(task))
    else:
        distributed = import_optional("distributed", "dask", "build_table(client=...)")
        futures = client.map(run, tasks, pure=False)
        for k, fut in enumerate(distributed.as_completed(futures), 1):
            report(k, fut.result())
        want = np.dtype(jnp.zeros(()).dtype)
        got = {np.dtype(np.asarray(s.los).dtype) for s in sims.values()}
        if got != {want}:
            raise ValueError(
                f"build_table: the dask workers computed in {', '.join(map(str, got))} but this "
                f"process uses {want}; set the same jax_enable_x64 on the workers, e.g. "
                "client.run(jax.config.update, 'jax_enable_x64', True)")
    meter.close(bar)
    sims = {b: sims[b] for b in betas}
    table = ResponseTable.from_simulations(
        list(sims.values()), mount=mounts, scan=scan, probe=probe,
        beam_gradient=np.stack([gradients[b] for b in betas]))
    return table, sims


def table_region(settings: Settings, betas: Sequence[float], scan, *, probe=None,
                 pitch: float = 0.0, roll: float = 0.0):
    """``(lo, hi)`` absolute CFD metres: the box every mount of `settings` at `betas` (with
    the installation's `pitch` and `roll`, degrees) samples (`lidarjax.scan_bounds` of all of
    them with the probe and the point reference); the region to load from each CFD run."""

    mount = settings_mount(settings, [float(b) for b in betas], pitch=pitch, roll=roll)
    return scan_bounds(scan, mount, np.asarray(settings.heights()), probe=probe)


#: How far `table_runs`' crop reaches beyond the nominal installation: tilt and turn,
#: degrees (the offsets `lidarjax.calibrate` can move the instrument to).
RUNS_MAX_TILT, RUNS_MAX_TURN = 3.0, 15.0


def table_runs(settings: Settings, betas: Sequence[float], field_for_beta: Callable,
               scan, *, u_ref=SEED_U_REF, probe=None, pitch: float = 0.0, roll: float = 0.0,
               max_tilt: float = RUNS_MAX_TILT, max_turn: float = RUNS_MAX_TURN
               ) -> TableRuns:
    """The CFD runs of `build_table` as a `lidarjax.TableRuns`, for
    `lidarjax.calibrate(..., runs=...)` (the table built again at the estimated
    installation).

    Every run is read (``field_for_beta(beta)``) cropped to the region that the installation
    turned by up to `max_turn` and tilted by up to `max_tilt` degrees from its nominal one
    (`pitch`, `roll`) samples, and **kept in memory** (a `TableRuns` holds them all); a
    `field_for_beta` that returns one object for several betas (one CFD run seen from
    rotated platforms) is held once. Arguments as `build_table`. Mesh cases are sampled on
    their resampling grid here (the exact cellPoint points of `build_table` belong to one
    installation); build the table to calibrate against as ``runs.table()``."""
    betas = [float(b) for b in betas]
    tilted = [settings_mount(settings, betas, pitch=pitch + dp, roll=roll + dr)
              for dp in (-max_tilt, max_tilt) for dr in (-max_tilt, max_tilt)]
    turned = [eqx.tree_at(lambda x: x.gamma, m, m.gamma + dg)
              for m in tilted for dg in (-max_turn, max_turn)]
    corners = jax.tree_util.tree_map(lambda *a: jnp.concatenate(a), *(tilted + turned))
    region = scan_bounds(scan, corners, np.asarray(settings.heights()), probe=probe)
    fields, cropped = [], {}  # id -> (the run as read, kept alive; its crop), one per object
    for b in betas:
        f = field_for_beta(b)
        if id(f) not in cropped:
            cropped[id(f)] = (f, f.crop(*region) if isinstance(f, GridField) else f)
        fields.append(cropped[id(f)][1])
    return TableRuns(fields, settings_mount(settings, betas, pitch=pitch, roll=roll), u_ref,
                     scan, np.asarray(settings.heights()), probe)


class _AtValue:
    """``field_for_beta`` of one profile-parameter value (picklable for dask)."""

    def __init__(self, field_for_run, value):
        self.field_for_run, self.value = field_for_run, value

    def __call__(self, beta, exact_at=None):
        if exact_at is not None and _takes_exact_at(self.field_for_run):
            return self.field_for_run(beta, self.value, exact_at=exact_at)
        return self.field_for_run(beta, self.value)


class _TableRun:
    """One run of `build_table`: load, crop to the region, simulate, return host arrays.
    A plain class (not a closure) so dask can ship it to workers."""

    def __init__(self, field_for_beta, scan, heights, u_ref, probe, lo, hi):
        self.field_for_beta = field_for_beta
        self.scan, self.heights, self.u_ref, self.probe = scan, heights, u_ref, probe
        self.lo, self.hi = lo, hi

    def __call__(self, task):
        beta, mount = task
        t0 = time.perf_counter()
        # a mesh (OpenFOAM, VTK) read by a loader that takes `exact_at` is made exact at the
        # points this mount samples: its own cellPoint there, as `lidarjax simulate --field`
        field = load_exact(self.field_for_beta, beta,
                           ExactPoints(self.scan, mount, self.heights, self.probe))
        shape = getattr(getattr(field, "grid", field), "shape", None)  # an exact mesh: its grid
        if isinstance(field, GridField):
            field = field.crop(self.lo, self.hi)
        crop = getattr(getattr(field, "grid", field), "shape", None)
        sim = simulate(field, self.scan, mount, jnp.asarray(self.heights), u_ref=self.u_ref,
                       probe=self.probe)
        # the velocity gradient along the beams, while the run is loaded (lidarjax.calibrate)
        gradient = np.asarray(beam_gradient(field, self.scan, mount, jnp.asarray(self.heights),
                                            probe=self.probe))
        del field
        sim = jax.tree_util.tree_map(np.asarray, sim)
        return beta, sim, {"shape": shape, "crop": crop, "seconds": time.perf_counter() - t0,
                           "gradient": gradient}
