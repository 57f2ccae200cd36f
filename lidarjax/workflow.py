"""The seed UDF's workflow on top of `simulate`: settings.dat in, seed output files out.

`simulate_settings` runs every platform rotation (beta) of a `Settings` in one compiled
batch when the CFD runs share a grid (one trace, ``jax.vmap`` over the runs), and
`seed_columns` turns a `Simulation` into the seed's 21 output columns.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .angles import horizontal_speed, seed_azimuth, wind_direction
from .batch import simulate_sectors, stack_fields
from .field import GridField
from .forward import Simulation, simulate
from .io.settings import Settings
from .mount import Mount

__all__ = ["seed_columns", "simulate_settings", "build_table", "table_region", "correct_records",
           "write_corrected_csv", "CorrectedRecords", "SEED_U_REF"]

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


def settings_mounts(settings: Settings, betas: Sequence[float]) -> list[Mount]:
    """The `Mount` of each platform rotation: the settings' location row for that beta and
    its gamma, psi and epsilon."""
    return [Mount(settings.location(b), beta=b, gamma=settings.gamma, psi=settings.psi,
                  epsilon=settings.epsilon) for b in betas]


def simulate_settings(
    settings: Settings,
    betas: Sequence[float],
    field_for_beta: Callable[[float], GridField],
    scan,
    *,
    u_ref=SEED_U_REF,
    probe=None,
) -> dict[float, Simulation]:
    """Simulate the lidar of `settings` for each platform rotation in `betas`.

    **Arguments:**

    - `settings`: a `lidarjax.io.Settings` (heights ``j * height / nh``, gamma, psi,
      epsilon and one location per beta).
    - `betas`: platform rotations (degrees) to run; each needs a location row.
    - `field_for_beta`: loads the CFD run of one beta (e.g. ``lidarjax.io.load_field``).
    - `scan`: the `lidarjax.Scan`.
    - `u_ref`: free-stream vector in the CFD frame (m/s); default the seed UDF's.
    - `probe`: probe volume (default point).

    **Returns:** ``{beta: Simulation}``. Runs on one grid are simulated in one compiled,
    vmapped batch; otherwise one call per run (one compilation per distinct grid shape).
    """
    betas = [float(b) for b in betas]
    mounts = settings_mounts(settings, betas)
    heights = jnp.asarray(settings.heights())
    fields = [field_for_beta(b) for b in betas]
    try:
        stacked = stack_fields(fields) if len(fields) > 1 else None
    except ValueError:  # runs on different grids: one call (and compilation) per grid
        stacked = None
    if stacked is None:
        return {b: simulate(f, scan, m, heights, u_ref=u_ref, probe=probe)
                for b, f, m in zip(betas, fields, mounts, strict=True)}
    batch = simulate_sectors(stacked, scan, mounts, heights, u_refs=u_ref, probe=probe)
    return {b: jax.tree_util.tree_map(lambda a, i=i: a[i], batch) for i, b in enumerate(betas)}


def build_table(
    settings: Settings,
    betas: Sequence[float],
    field_for_beta: Callable[[float], GridField],
    scan,
    *,
    u_ref=SEED_U_REF,
    probe=None,
    client=None,
    progress: bool = False,
):
    """A `lidarjax.ResponseTable` from the CFD runs of a seed settings file.

    Each platform rotation ``beta`` is one inflow direction; the table's directions are the
    free streams' meteorological directions in the north frame. Returns ``(table, sims)``.

    Runs are loaded **one at a time**: each `GridField` returned by `field_for_beta` is cut
    at once to `scan_bounds` of all mounts (with the probe; `GridField.crop`, bit-exact),
    simulated, and dropped, so the peak memory is about one run whatever their number.
    `field_for_beta` may load only that region itself (``lidarjax.io.load_field(path,
    region=...)``, with `table_region` giving it); any other `AbstractField` (an analytic
    scene) is used as it is.

    **Arguments** (besides those of `simulate_settings`):

    - `client`: a ``dask.distributed.Client``; runs are then read and simulated in parallel
      on its workers (`field_for_beta` is shipped to them, so it must be picklable by
      cloudpickle and read files the workers can see). The workers must use the caller's
      ``jax_enable_x64`` setting (checked: the command line sets it on them). The table is
      identical to the serial one.
    - `progress`: one line per finished run on stderr (run, beta, grid before and after the
      crop, seconds).
    """
    import sys

    from .response import ResponseTable

    betas = [float(b) for b in betas]
    mounts = settings_mounts(settings, betas)
    heights = np.asarray(settings.heights())
    lo, hi = table_region(settings, betas, scan, probe=probe)
    u_ref = np.asarray(u_ref, np.float64)
    tasks = [(b, m) for b, m in zip(betas, mounts, strict=True)]
    run = _TableRun(field_for_beta, scan, heights, u_ref, probe, lo, hi)
    sims: dict[float, Simulation] = {}

    def report(k, result):
        b, sim, info = result
        sims[b] = sim
        if progress:
            print(f"table: run {k}/{len(betas)} beta {b:g}: grid {info['shape']} -> crop "
                  f"{info['crop']} in {info['seconds']:.1f} s", file=sys.stderr)

    if client is None:
        for k, task in enumerate(tasks, 1):
            report(k, run(task))
    else:
        from .io._common import import_optional

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
    sims = {b: sims[b] for b in betas}
    table = ResponseTable.from_simulations(list(sims.values()), mount=mounts)
    return table, sims


def table_region(settings: Settings, betas: Sequence[float], scan, *, probe=None):
    """``(lo, hi)`` absolute CFD metres: the box every mount of `settings` at `betas` samples
    (`lidarjax.scan_bounds` of all of them with the probe and the point reference); the
    region to load from each CFD run."""
    from .footprint import scan_bounds

    mounts = settings_mounts(settings, [float(b) for b in betas])
    return scan_bounds(scan, mounts, np.asarray(settings.heights()), probe=probe)


class _TableRun:
    """One run of `build_table`: load, crop to the region, simulate, return host arrays.
    A plain class (not a closure) so dask can ship it to workers."""

    def __init__(self, field_for_beta, scan, heights, u_ref, probe, lo, hi):
        self.field_for_beta = field_for_beta
        self.scan, self.heights, self.u_ref, self.probe = scan, heights, u_ref, probe
        self.lo, self.hi = lo, hi

    def __call__(self, task):
        import time

        beta, mount = task
        t0 = time.perf_counter()
        field = self.field_for_beta(beta)
        shape = getattr(field, "shape", None)
        if isinstance(field, GridField):
            field = field.crop(self.lo, self.hi)
        crop = getattr(field, "shape", None)
        sim = simulate(field, self.scan, mount, jnp.asarray(self.heights), u_ref=self.u_ref,
                       probe=self.probe)
        del field
        sim = jax.tree_util.tree_map(np.asarray, sim)
        return beta, sim, {"shape": shape, "crop": crop, "seconds": time.perf_counter() - t0}


@dataclasses.dataclass(frozen=True)
class CorrectedRecords:
    """Corrected records (`correct_records`); arrays ``(r, h)`` unless noted.

    - `kind`: 'sta', 'rtd' or 'zephir'; `time` ``(r,)`` datetime64 (end of interval);
      `heights` ``(h,)`` m above the lidar (the table's);
    - `speed`, `direction`: free-stream horizontal speed (m/s) and meteorological direction
      (degrees), NaN where not converged; `speed_std`, `direction_std`: one-sigma;
    - `converged`, `flags` (`lidarjax.InverseFlag` bits);
    - `measured_speed`, `measured_direction`: what the instrument reported (for raw LOS
      records, the homogeneous-flow reconstruction).
    """

    kind: str
    time: np.ndarray
    heights: np.ndarray
    speed: np.ndarray
    direction: np.ndarray
    speed_std: np.ndarray
    direction_std: np.ndarray
    converged: np.ndarray
    flags: np.ndarray
    measured_speed: np.ndarray
    measured_direction: np.ndarray


def _match_heights(table_heights, record_heights, path) -> np.ndarray:
    if table_heights is None:
        raise ValueError("the response table has no heights; rebuild it with lidarjax table")
    th = np.asarray(table_heights, np.float64)
    rh = np.asarray(record_heights, np.float64)
    idx = np.array([int(np.argmin(np.abs(rh - h))) for h in th])
    bad = [f"{h:g}" for h, i in zip(th, idx, strict=True) if abs(rh[i] - h) > 0.5]
    if bad:
        raise ValueError(
            f"{path}: the table's heights {', '.join(bad)} m are not among the record's "
            f"heights {', '.join(f'{h:g}' for h in rh)} m; build the table at the record's heights")
    return idx


def _chunks(n: int, size: int, progress: bool, label: str):
    starts = range(0, n, size)
    if not progress:
        return starts
    try:
        from tqdm import tqdm
    except ImportError:
        return _text_progress(starts, n, size, label)
    return tqdm(starts, total=len(starts), desc=label, unit="chunk")


def _text_progress(starts, n, size, label):
    import sys

    for s in starts:
        yield s
        done = min(n, s + size)
        print(f"\r{label}: {done}/{n} records", end="" if done < n else "\n", file=sys.stderr)


def correct_records(
    table,
    path,
    *,
    noise: float | None = None,
    chunk_records: int = 4096,
    progress: bool = False,
) -> CorrectedRecords:
    """Read a record file and invert every record and height with `table`.

    - ``.sta`` / ``.stdsta`` (Windcube statistics): `lidarjax.invert_reconstructed` on the
      reported speed and direction (`noise` is then the component noise, m/s);
    - ``.rtd`` (Windcube real-time LOS): 10-minute beam means, then `lidarjax.invert` on the
      raw LOS (beams 0, 90, 180, 270 and the vertical, as many as the table has);
    - ``.csv`` (ZephIR 10-minute export): `invert_reconstructed`.

    The table's heights must be among the record's (within 0.5 m). Records are processed in
    chunks of `chunk_records` (one compiled shape; the last chunk is padded), with a progress
    bar when asked (tqdm if installed). Bad records come back NaN, never an exception.
    """
    from pathlib import Path

    from .inverse import invert, invert_reconstructed
    from .io import group_rtd, read_rtd, read_sta, read_zephir_csv

    p = Path(path)
    suffix = p.suffix.lower()
    reported = {".sta": ("sta", read_sta), ".stdsta": ("sta", read_sta),
                ".csv": ("zephir", read_zephir_csv)}
    if suffix in reported:  # the instrument's reconstructed speed and direction
        kind, reader = reported[suffix]
        rec = reader(p)
        time, heights = rec.time, rec.heights
        idx = _match_heights(table.heights, heights, p)
        data = (rec.speed[:, idx], rec.direction[:, idx])
        measured = data
    elif suffix == ".rtd":
        beams = group_rtd(read_rtd(p))
        kind, time, heights = "rtd", beams.time, beams.heights
        idx = _match_heights(table.heights, heights, p)
        los = beams.los[:, idx, : table.n_beams]
        data = (los,)
        vectors = np.asarray(table.beam_vectors) if table.beam_vectors is not None else None
        if vectors is not None:
            homog = np.einsum("kb,rhb->rhk", np.linalg.pinv(vectors), np.nan_to_num(los))
            homog[np.isnan(los).any(-1)] = np.nan
        else:
            homog = np.full(los.shape[:-1] + (3,), np.nan)
        measured = (np.asarray(horizontal_speed(homog)), np.asarray(wind_direction(homog)))
    else:
        raise ValueError(f"{p}: unknown record format {suffix!r}; expected .sta, .stdsta, .rtd "
                         "or a ZephIR .csv")
    n = len(time)
    dtype = np.asarray(table.response).dtype
    out = {k: [] for k in ("speed", "direction", "speed_std", "direction_std", "converged",
                           "flags")}
    size = max(1, min(chunk_records, n))
    for s in _chunks(n, size, progress, f"correcting {p.name}"):
        part = [np.asarray(a[s:s + size], dtype) for a in data]
        m = part[0].shape[0]
        if m < size:  # pad to the compiled shape with NaN records
            part = [np.concatenate([a, np.full((size - m,) + a.shape[1:], np.nan, dtype)])
                    for a in part]
        if kind == "rtd":
            inv = invert(table, part[0], noise=noise)
        else:
            inv = invert_reconstructed(table, part[0], part[1], noise=noise)
        for k in out:
            out[k].append(np.asarray(getattr(inv, k))[:m])
    res = {k: np.concatenate(v) if v else np.zeros((0, len(idx))) for k, v in out.items()}
    return CorrectedRecords(kind=kind, time=np.asarray(time),
                            heights=np.asarray(table.heights, np.float64),
                            measured_speed=np.asarray(measured[0], np.float64),
                            measured_direction=np.asarray(measured[1], np.float64), **res)


def write_corrected_csv(path, corrected: CorrectedRecords, metadata: dict | None = None):
    """Write corrected records as a long CSV (one row per record and height), atomically.

    Header comment lines carry `metadata`; columns: time (ISO 8601, end of interval),
    height [m], speed [m/s], direction [deg, meteorological], speed_std [m/s],
    direction_std [deg], converged [bool], flags [InverseFlag bits], measured_speed [m/s],
    measured_direction [deg].
    """
    from .io._common import atomic_write_text

    lines = [f"# {k}: {v}" for k, v in (metadata or {}).items()]
    lines.append("time,height [m],speed [m/s],direction [deg],speed_std [m/s],"
                 "direction_std [deg],converged,flags,measured_speed [m/s],"
                 "measured_direction [deg]")
    c = corrected

    def f(v):
        return "nan" if not np.isfinite(v) else f"{v:.6g}"

    for i, t in enumerate(c.time):
        ts = str(np.datetime64(t, "s"))
        for j, h in enumerate(c.heights):
            lines.append(",".join([
                ts, f"{h:g}", f(c.speed[i, j]), f(c.direction[i, j]), f(c.speed_std[i, j]),
                f(c.direction_std[i, j]), str(bool(c.converged[i, j])), str(int(c.flags[i, j])),
                f(c.measured_speed[i, j]), f(c.measured_direction[i, j])]))
    return atomic_write_text(path, "\n".join(lines) + "\n")
