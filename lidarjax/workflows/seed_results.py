"""Write the seed workflow's results and explain the NaNs in them (the files of
``lidarjax simulate`` and ``lidarjax monitor-points --sampled``).

`write_seed_results` writes, for each platform rotation (beta) of a ``{beta: Simulation}``
(from `lidarjax.simulate_settings` or `lidarjax.simulate_from_monitor_points`), into a
folder:

- ``windcube simulation <beta> degrees.dat``: the seed UDF's 21 columns
  (`lidarjax.io.write_seed_output`, `lidarjax.workflows.seed_tables.seed_columns`) with the
  `lidarjax.Flag` bits per height as a 22nd column;
- ``simulation_<beta>.csv``: the same columns with units and metadata (settings, CFD data,
  scan, angles, free stream);
- ``simulation_<beta>.nc``: the same as NetCDF (only with the optional ``xarray``).

Units and frames as the seed's: heights in metres above the lidar, speeds in m/s in the
CFD frame, ``Th_lidar`` / ``th_point`` in the seed's azimuth (flow heading clockwise from
CFD ``+x``; meteorological = (seed + 270) mod 360), factors as in `lidarjax.corrections`.

`explain_nans` turns NaN results into one line: a CFD field NaN everywhere, a lidar off the
grid, a grid too low, or beams crossing NaN cells (decoding `lidarjax.Flag.BEAM_OUTSIDE`).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import numpy as np

from .._util import PathLike, have_module
from ..field import GridField
from ..flags import Flag
from ..forward import Simulation
from ..io import write_netcdf, write_seed_output, write_table_csv
from ..io.seed_output import SEED_UNITS, format_number, seed_output_filename
from ..io.settings import Settings
from .seed_tables import seed_columns

__all__ = ["write_seed_results", "explain_nans", "seed_result_files"]

_DIRECTIONS = ("Th_lidar/th_point: seed azimuth = (-atan2(v,u)) mod 360; "
               "meteorological = (seed + 270) mod 360")


def seed_result_files(betas: Sequence[float]) -> list[str]:
    """The file names `write_seed_results` writes for `betas` (NetCDF only with xarray), for
    checking an output folder before computing."""
    nc = have_module("xarray")
    names = []
    for b in betas:
        names += [seed_output_filename(b), f"simulation_{format_number(b)}.csv"]
        if nc:
            names.append(f"simulation_{format_number(b)}.nc")
    return names


def write_seed_results(
    out: PathLike,
    settings: Settings,
    sims: Mapping[float, Simulation],
    *,
    scan: str,
    u_ref: Sequence[float],
    sources: Mapping[float, str] | str,
    settings_file: PathLike | None = None,
    pitch: float = 0.0,
    roll: float = 0.0,
    log: Callable[[str], None] | None = None,
) -> list[Path]:
    """Write the seed files, CSV and (with xarray) NetCDF tables of `sims` ``{beta:
    Simulation}`` to the folder `out` (created; module docs).

    **Arguments:** `settings` (its `verbose` picks the seed file's layout; gamma, psi and
    epsilon go to the metadata); `scan`: the scan's name; `u_ref`: the free stream in the
    CFD frame (m/s); `sources`: the CFD data of each beta (``{beta: text}``, or one text for
    all); `settings_file`: the settings' file name in the metadata (default
    ``settings.source``); `pitch`, `roll`: the installation's tilt, degrees; `log`: called
    with a header, one line per beta (file, lidar speed at the top height, ``cff_U`` range)
    and a summary (e.g. ``print``; default silent).

    **Returns:** the paths written."""

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    nc = have_module("xarray")
    log = log or (lambda line: None)
    settings_file = settings.source if settings_file is None else settings_file
    flag_doc = ", ".join(f"{int(f)} {f.name.lower()}" for f in Flag if f)
    written = []
    log(f"{'beta':>7s} {'file':<40s} {'U_lidar(top)':>13s} {'cff_U range':>18s}")
    for b, sim in sims.items():
        cols = seed_columns(sim)
        flags = np.asarray(sim.flags).astype(np.int64)
        path = write_seed_output(out, b, cols, verbose=settings.verbose, flags=flags)
        source = sources if isinstance(sources, str) else sources[b]
        meta = {"settings": str(settings_file), "field": source, "scan": scan,
                "beta_deg": b, "gamma_deg": settings.gamma, "psi_deg": settings.psi,
                "epsilon_deg": settings.epsilon, "pitch_deg": pitch,
                "roll_deg": roll, "u_ref_cfd_m_s": ",".join(map(str, u_ref)),
                "directions": _DIRECTIONS,
                "flags": f"lidarjax.Flag bits per height: {flag_doc}"}
        with_flags = {**cols, "flags": flags.astype(np.float64)}
        units = {**SEED_UNITS, "flags": "bits"}
        written += [path, write_table_csv(out / f"simulation_{format_number(b)}.csv",
                                          with_flags, units, meta)]
        if nc:
            written.append(write_netcdf(out / f"simulation_{format_number(b)}.nc", with_flags,
                                        meta, units=units))
        cff = cols["cff_U"]
        rng = (f"{np.nanmin(cff):8.4f}..{np.nanmax(cff):8.4f}" if np.isfinite(cff).any()
               else f"{'nan':>18s}")
        log(f"{b:7.1f} {path.name:<40s} {cols['U_mag_lidar'][-1]:13.3f} {rng}")
    extra = " and NetCDF" if nc else ""
    log(f"wrote {len(sims)} seed file(s), CSV{extra} table(s) to {out}")
    return written


def explain_nans(sims: Mapping[float, Simulation], fields: Mapping[float, GridField],
                 settings: Settings, sources: Mapping[float, PathLike]) -> str | None:
    """One line explaining why values of `sims` ``{beta: Simulation}`` are NaN, or None.

    `fields` ``{beta: field}`` are the CFD runs simulated (gridded: their extent tells a
    lidar off the grid or a grid too low), `sources` ``{beta: file}`` name them. Decodes
    `lidarjax.Flag.BEAM_OUTSIDE`; at most two reasons are spelled out."""

    lidar = np.concatenate([np.asarray(s.lidar_velocity)[..., 0].ravel() for s in sims.values()])
    n_nan = int(np.count_nonzero(~np.isfinite(lidar)))
    if lidar.size == 0 or n_nan == 0:
        return None
    head = ("most values are NaN" if n_nan > lidar.size / 2 else
            f"{n_nan} of {lidar.size} height-runs are NaN")
    reasons = []
    for b, sim in sims.items():
        f = fields[b]
        vel = np.asarray(f.velocity)
        if not np.isfinite(vel).any():
            reasons.append(f"the CFD field {sources[b]} is NaN everywhere")
            continue
        flags = np.asarray(sim.flags)
        if not (flags & int(Flag.BEAM_OUTSIDE)).any():
            continue
        loc = np.asarray(settings.location(b), np.float64)
        origin = np.asarray(f.origin, np.float64) + np.asarray(getattr(f, "origin_lo", 0.0))
        lo = origin + np.array([float(np.min(a)) for a in (f.x_local, f.y_local, f.z_local)])
        hi = origin + np.array([float(np.max(a)) for a in (f.x_local, f.y_local, f.z_local)])
        top = loc[2] + float(np.max(settings.heights()))
        if np.any(loc[:2] < lo[:2]) or np.any(loc[:2] > hi[:2]):
            reasons.append(f"beta {b:g}: the lidar at x={loc[0]:g}, y={loc[1]:g} m is off the "
                           f"CFD grid (x {lo[0]:g}..{hi[0]:g}, y {lo[1]:g}..{hi[1]:g} m)")
        elif top > hi[2]:
            reasons.append(f"beta {b:g}: the grid is too low (top z={hi[2]:g} m, highest "
                           f"measurement z={top:g} m)")
        else:
            n = int(np.count_nonzero(flags & int(Flag.BEAM_OUTSIDE)))
            reasons.append(f"beta {b:g}: {n} heights have beams outside the grid or in a solid "
                           "(NaN cells)")
    if not reasons:
        return f"{head}; see the flags column (lidarjax.Flag bits)"
    more = f" (+{len(reasons) - 2} more)" if len(reasons) > 2 else ""
    return f"{head}: " + "; ".join(reasons[:2]) + more
