"""`lidarjax series`: a lidar's simulated 10-minute statistics in frozen turbulence over a
mean flow -> a simulated ``.sta``, the statistics as CSV and lidar against point TI.

The field is `lidarjax.series_field` (`lidarjax.workflows.series_run`), the statistics
`lidarjax.simulate_statistics` and the files `lidarjax.write_series_report`; this module
parses, checks the options and prints.

A scanning ``--scan`` (a preset ``ppi``, ``rhi``, ``stare``, ``vad``, ``rosette`` or the layout
of a Halo ``.hpl`` / Windcube ``.nc`` scan file) is flown through the same field in time
instead (`lidarjax.scanning.simulate_scan_series`, ``--scans N`` repetitions or as many as
cover ``--hours``, in compiled batches): the files are ``series_scan.nc`` (CF NetCDF, time x
beam x range), ``series_scan.png`` (the last scan on its cone or plane) and, for a PPI or
VAD of at least 3 rays, ``series_vad.csv`` (the VAD wind profile of every scan, `lidarjax.scanning.vad_fit`).
The 10-minute ``.sta`` statistics are the profilers' and are not written for a scanning scan.

A fixed lidar's mean flow is read only where its beams look (`lidarjax.scan_bounds`, or the
scanning scan's region, with the height the advection is taken from), and an OpenFOAM or VTK
mean flow is made exact there, the mesh's own cellPoint, at every point the lidar samples
(the same at every time), as `lidarjax simulate` does. With ``--motion`` the lidar samples
other points at every time: the whole mean flow is read and its graded grid answers.
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import equinox as eqx
import numpy as np

from .. import scan as scans
from ..angles import wind_direction
from ..beam import ExactPoints
from ..footprint import scan_bounds
from ..io import load_field_sequence, read_motion_csv, read_settings, write_scan_netcdf, write_table_csv
from ..io.fields import load_field
from ..mount import Mount
from ..probe import PointProbe
from ..scanning import ScanResult, scan_points, simulate_scan_series, vad_fit
from ..scenes import uniform
from ..series import RECORD_LENGTH, probe_for_field, simulate_series, simulate_statistics
from ..timing import schedule_for
from ..workflows.series_report import write_series_csv, write_series_report
from ..workflows.series_run import mean_wind_above, series_field
from ._common import (
    add_command,
    add_probe_arguments,
    add_settings_argument,
    check_output_folder,
    field_input,
    finite_float,
    input_case,
    input_file,
    input_files,
    make_probe,
    make_scan,
    positive_float,
    positive_int,
    print_height_means,
    vector,
)
from ._scanning import (
    add_scan_pattern_arguments,
    check_scan_options,
    describe,
    plot_scan,
    read_scan_source,
    scan_choice,
    scan_region,
    scanning_probe,
)

#: Gate samples (rays x gates x sub-rays x probe nodes) per compiled batch of a scanning scan.
SCAN_BATCH_SAMPLES = 20_000_000


def _ints(text: str) -> tuple[int, int, int]:
    try:
        values = tuple(int(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three integers 'nx,ny,nz', got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three integers 'nx,ny,nz', got {text!r}")
    return values


def _mean_flow(text: str) -> str:
    """argparse type of ``--field``: 'uniform' or an existing CFD field file or mesh."""
    return text if text == "uniform" else field_input(text)


def register(sub) -> None:
    p = add_command(
        sub, "series", run,
        "simulated 10-minute statistics (.sta) in frozen turbulence over a mean flow",
        "Simulate every line of sight at the time it is taken through a turbulence "
        "box advected over a mean flow (Taylor), build the instrument's "
        "reconstructions and reduce them to 10-minute statistics: a simulated .sta "
        "(speed, dispersion, min, max, direction, Z-wind, availability), a CSV with "
        "lidar, cup and sonic statistics, and a figure of lidar TI against point TI "
        "per height. The lidar location and heights come from the seed settings.dat.",
        epilog="examples:\n"
        "  lidarjax series settings.dat --field uniform --speed 10 --direction 270 "
        "--generate-box 512,32,32 --out series/\n"
        "  lidarjax series settings.dat --field run.npz --box turb.bts --scan zephir "
        "--hours 6 --out series/\n"
        "  lidarjax series settings.dat --field run.npz --box u.bin,v.bin,w.bin "
        "--box-shape 8192,32,32 --box-spacing 2,4,4 --out series/\n"
        "  lidarjax series settings.dat --field uniform --speed 8 --direction 270 "
        "--generate-box 512,32,32 --scan vad --elevation 60 --gates 40 --scans 20 "
        "--out vad/\n\n"
        "A scanning --scan (a preset or a .hpl / .nc scan file) is flown through the "
        "same field in time instead: --scans N repetitions (default: as many as cover "
        "--hours). It writes series_scan.nc (CF NetCDF, time x beam x range: LOS, ray "
        "times, azimuth, elevation, flags), series_scan.png (the last scan on its cone or "
        "plane; not with --no-plots) and, for a PPI or VAD of 3 rays or more, "
        "series_vad.csv (each scan's VAD wind profile per gate). The 10-minute .sta "
        "statistics are the profilers' and "
        "are not written for a scanning scan.",
        raw=True)
    add_settings_argument(p, "location, angles, heights")
    p.add_argument("--beta", type=finite_float, default=None,
                   help="platform rotation row to use (default: the file's beta)")
    _flow_arguments(p)
    _box_arguments(p)
    _instrument_arguments(p)
    _output_arguments(p)


def _flow_arguments(p) -> None:
    """The mean flow (--field) or an unsteady run's snapshots (--sequence)."""
    p.add_argument("--field", default=None, type=_mean_flow,
                   help="mean flow: a CFD field file (.npz, .nc, Fluent ASCII), an OpenFOAM case "
                        "or VTK mesh (its own cellPoint at the points a fixed lidar samples), or "
                        "'uniform' (uniform wind of --speed from --direction)")
    p.add_argument("--sequence", default=None, metavar="CASE", type=input_case,
                   help="instead of --field and a box: an OpenFOAM case of an unsteady run (LES, "
                        "URANS); the profiler flies through its time directories, each LOS at its "
                        "own time (linear between snapshots; a fixed lidar exact, the mesh's own "
                        "cellPoint, at every point it samples). Writes series_los.csv and "
                        "series_wind.csv")
    p.add_argument("--time-range", default=None, metavar="FIRST,LAST",
                   help="--sequence: the snapshots between these times (s) only (default all)")
    p.add_argument("--max-snapshots", type=positive_int, default=8,
                   help="--sequence: the most snapshots held in memory at once (default 8)")


def _box_arguments(p) -> None:
    """The turbulence box (read or generated) and its advection."""
    box = p.add_mutually_exclusive_group()
    box.add_argument("--box", type=input_files,
                     help="turbulence box: a TurbSim .bts file, or three HAWC2 binary files "
                          "'u.bin,v.bin,w.bin' (with --box-shape)")
    box.add_argument("--generate-box", type=_ints, metavar="NX,NY,NZ",
                     help="generate a periodic Mann box of this many nodes")
    p.add_argument("--box-shape", type=_ints, default=None, help="HAWC2 box nodes nx,ny,nz")
    p.add_argument("--box-spacing", type=vector, default=(4.0, 4.0, 4.0),
                   help="box node spacing dx,dy,dz in metres (default 4,4,4)")
    p.add_argument("--length-scale", type=positive_float, default=30.0, help="Mann L, m (default 30)")
    p.add_argument("--gamma", type=finite_float, default=3.9, help="Mann Gamma (default 3.9)")
    p.add_argument("--ti", type=positive_float, default=0.10,
                   help="generated box: sigma_u = ti * advection speed (default 0.10)")
    p.add_argument("--seed", type=int, default=0, help="generated box: random seed")
    p.add_argument("--generator", choices=("builtin", "hipersim"), default="builtin",
                   help="box generator: lidarjax's numpy FFT (default) or hipersim (extra "
                        "'turbulence')")
    p.add_argument("--speed", type=positive_float, default=None,
                   help="advection speed, m/s (default: the mean flow above the lidar at the "
                        "top height; required for --field uniform)")
    p.add_argument("--direction", type=finite_float, default=None,
                   help="advection direction, degrees from CFD +y, meteorological (default: "
                        "the mean flow's there)")


def _instrument_arguments(p) -> None:
    """The instrument: scan, timing, tilt, motion and probe volume."""
    p.add_argument("--scan", type=scan_choice, default="windcube_v2",
                   help="a profiler (windcube_v1, windcube_v2 default, zephir), a scanning "
                        "preset (ppi, rhi, stare, vad, rosette) or a Halo .hpl / Windcube .nc "
                        "scan file (its rays, gates and times)")
    p.add_argument("--cone-angle", type=positive_float, default=None,
                   help="cone angle in degrees (default: the scan's)")
    p.add_argument("--seconds-per-los", type=positive_float, default=None,
                   help="override the scan's time per LOS (defaults: V1 1.5, V2 1.0, ZephIR "
                        "0.02 s)")
    p.add_argument("--tilt-compensation", action="store_true",
                   help="the instrument corrects its reconstruction for its tilt")
    p.add_argument("--motion", default=None, type=input_file,
                   help="platform motion log CSV (time,surge,sway,heave,pitch,roll,yaw)")
    add_probe_arguments(p)
    p.set_defaults(probe="auto")


def _output_arguments(p) -> None:
    """The simulated span, batching and outputs, and the scanning scans' pattern."""
    p.add_argument("--start", default="2024-01-01T00:00",
                   help="date and time of the first record's start (default 2024-01-01T00:00)")
    p.add_argument("--hours", type=positive_float, default=24.0,
                   help="hours simulated, whole 10-minute records (default 24)")
    p.add_argument("--chunk", type=positive_int, default=None,
                   help="records per compiled batch (default 36); scanning scans: scans per "
                        "batch (default: chosen for the scan's size)")
    p.add_argument("--no-plots", action="store_true", help="skip the figure")
    p.add_argument("--out", default=".", help="output folder (default: .)")
    add_scan_pattern_arguments(p, title="scanning scans (a preset or a scan file)")
    p.add_argument("--scans", type=positive_int, default=None,
                   help="scanning scans: repetitions flown (default: as many as cover --hours)")


def run(args) -> int:
    scanning = check_scan_options(args, profiler_only=(
        ("--cone-angle", args.cone_angle is not None),
        ("--seconds-per-los (a scan's timing is its --accumulation)",
         args.seconds_per_los is not None),
        ("--tilt-compensation", args.tilt_compensation)))
    if not scanning and args.scans is not None:
        raise ValueError(f"--scans applies to scanning scans, not to the profiler {args.scan} "
                         "(its length is --hours); drop it or give e.g. --scan ppi")
    settings = read_settings(args.settings)
    beta = float(settings.beta if args.beta is None else args.beta)
    location = settings.location(beta)
    heights = np.asarray(settings.heights())
    try:
        start = np.datetime64(args.start, "s")
    except ValueError:
        raise ValueError(f"--start {args.start!r} is not a date and time (e.g. 2024-01-01T00:00)") from None
    if args.sequence is not None:
        if scanning:
            raise ValueError(f"--sequence flies a profiler; {args.scan} is a scanning scan "
                             "(use --field and a box)")
        given = [o for o, v in (("--field", args.field), ("--box", args.box),
                                ("--generate-box", args.generate_box)) if v is not None]
        if given:
            raise ValueError(f"--sequence is the whole flow (its snapshots are the turbulence); "
                             f"drop {', '.join(given)}")
    else:
        if args.field is None:
            raise ValueError("give --field (a mean flow, with --box or --generate-box) or "
                             "--sequence CASE (an unsteady run's snapshots)")
        if args.box is None and args.generate_box is None:
            raise ValueError("--field needs a turbulence box: --box or --generate-box")
    if scanning:
        return run_scanning(args, settings, beta, location, heights, start)
    if args.sequence is not None:
        return run_sequence(args, settings, beta, location, heights, start)
    n_rec = int(np.floor(args.hours * 3600.0 / RECORD_LENGTH + 1e-9))
    if n_rec < 1:
        raise ValueError(f"--hours {args.hours} holds no whole 10-minute record")
    if args.ti <= 0:
        raise ValueError(f"--ti must be positive, got {args.ti}")
    scan, probe, schedule, mount, motion = _profiler(args, settings, beta, location)
    auto_nodes = args.probe_nodes is None and probe is not None

    # what simulate_statistics samples: simulate's geometry and node choice, with the mount
    points = ExactPoints(scan, mount, heights, probe)

    # a moving lidar samples other points at every time: the graded grid of a mesh then, and
    # the whole mean flow (its excursions are not bounded here)
    fixed = motion is None
    region = scan_bounds(scan, mount, heights, probe=probe) if fixed else None
    field, info = build_field(args, settings, beta, location, heights,
                              exact_points=points if fixed else None, region=region)
    starts = np.arange(n_rec) * RECORD_LENGTH
    if auto_nodes:  # explicit --probe-nodes kept as given
        # the nodes that resolve the box, chosen here once so that they can be shown
        probe = probe_for_field(field, scan, heights, probe, mount=mount, caller="lidarjax series")
    label = f"{type(probe).__name__}, {probe.n_nodes} nodes" if probe else "point probe"
    print(f"lidarjax series: {args.scan} ({label}), {heights.size} heights, {n_rec} records; "
          f"{info}")
    stats = simulate_statistics(field, scan, mount, heights, starts, schedule=schedule,
                                probe=probe, motion=motion, chunk=args.chunk or 36,
                                refine_probe=False)
    meta = {"settings": str(args.settings), "field": args.field, "scan": args.scan,
            "beta_deg": beta, "box": info, "start": str(start)}
    res = write_series_report(Path(args.out), stats, heights, starts, start_datetime=start,
                              scan=scan, metadata=meta, plots=not args.no_plots,
                              label=args.scan)
    print_height_means(heights, {"U_lidar": (stats.speed, 8, 3), "TI_lidar": (stats.ti, 9, 4),
                                 "TI_cup": (stats.cup_ti, 7, 4),
                                 "TI_sonic": (stats.sonic_ti, 9, 4),
                                 "avail%": (stats.availability, 7, 1)})
    wrote = [str(res["sta"]), str(res["csv"])] + ([str(res["plot"])] if res["plot"] else [])
    print("wrote " + ", ".join(wrote) + (f" ({res['note']})" if res["note"] else ""))
    return 0


def _profiler(args, settings, beta, location):
    """The profiler of the arguments: ``(scan, probe, schedule, mount, motion)``."""
    scan = make_scan(args.scan, args.cone_angle)
    if args.tilt_compensation:
        make = getattr(scans, args.scan)
        scan = (make(tilt_compensation=True) if args.cone_angle is None
                else make(args.cone_angle, tilt_compensation=True))
    if args.probe == "auto":
        args.probe = "cw" if args.scan == "zephir" else "pulsed"
    probe = make_probe(args)
    schedule = schedule_for(scan, seconds_per_los=args.seconds_per_los)
    mount = Mount(location, beta=beta, gamma=settings.gamma, psi=settings.psi,
                  epsilon=settings.epsilon)
    motion = read_motion_csv(args.motion) if args.motion else None
    return scan, probe, schedule, mount, motion


def run_sequence(args, settings, beta, location, heights, start) -> int:
    """A profiler flown through an unsteady OpenFOAM run's snapshots (`--sequence`):
    `lidarjax.io.load_field_sequence` made exact at the points a fixed lidar samples
    (`lidarjax.ExactPoints`, the nodes `simulate_series` chooses; no graded grid per
    snapshot), `lidarjax.simulate_series` over every whole scan cycle within the snapshots'
    span, `lidarjax.workflows.series_report.write_series_csv`. A moving lidar samples the
    graded grid of each snapshot instead."""
    scan, probe, schedule, mount, motion = _profiler(args, settings, beta, location)
    time_range = None
    if args.time_range is not None:
        try:
            time_range = tuple(float(v) for v in args.time_range.split(","))
        except ValueError:
            time_range = ()
        if len(time_range) != 2 or not all(np.isfinite(time_range)) or time_range[1] <= time_range[0]:
            raise ValueError(f"--time-range {args.time_range!r}: expected two increasing times "
                             f"'FIRST,LAST' in seconds")
    inputs = [("settings", args.settings), ("--sequence", args.sequence), ("--motion", args.motion)]
    out = check_output_folder(args.out, files=("series_los.csv", "series_wind.csv"), inputs=inputs)
    fixed = motion is None
    points = ExactPoints(scan, mount, heights, probe) if fixed else None
    region = scan_bounds(scan, mount, heights, probe=probe) if fixed else None
    seq = load_field_sequence(args.sequence, region=region, time_range=time_range,
                              max_snapshots=args.max_snapshots, exact_at=points,
                              grid_fallback=not fixed)
    t0, t1 = (float(t) for t in seq.time_span)
    series = simulate_series(seq, scan, mount, heights, (t0, t1 - t0), schedule=schedule,
                             probe=probe, motion=motion)
    used = probe if points is None else points.probe
    label = (f"{type(used).__name__}, nodes per height {_node_counts(used, heights.size)}"
             if used is not None and not isinstance(used, PointProbe) else "point probe")
    los = np.asarray(series.los)
    print(f"lidarjax series: {args.scan} ({label}) through {len(seq)} snapshots of "
          f"{args.sequence}, {t0:g}..{t1:g} s: {los.shape[0]} cycles, "
          f"{int(np.isfinite(los).sum())}/{los.size} LOS finite"
          + ("; exact cellPoint at every point sampled" if fixed else
             "; a moving lidar: the graded grid of each snapshot"))
    meta = {"settings": str(args.settings), "sequence": str(args.sequence), "scan": args.scan,
            "beta_deg": beta, "start": str(start), "snapshots": len(seq)}
    res = write_series_csv(out, series, metadata=meta)
    point = np.hypot(*np.moveaxis(np.asarray(series.point_velocity)[..., :2], -1, 0))
    print_height_means(heights, {"U_lidar": (series.speed, 8, 3), "U_point": (point, 8, 3)},
                       what="scan cycle")
    print(f"wrote {res['los']}, {res['wind']}")
    return 0


def _node_counts(probe, n_heights: int) -> tuple[int, ...]:
    counts = getattr(probe, "node_counts", None)
    return tuple(counts) if counts is not None else (probe.n_nodes,) * n_heights


def build_field(args, settings, beta, location, heights, exact_points=None, region=None):
    """The frozen-turbulence field of the arguments and a one-line description
    (`lidarjax.series_field`, with the options checked and named here).

    `region`: ``(lo, hi)`` absolute CFD metres, the box the series samples (with the point
    ``heights[-1]`` above the lidar, where the advection is taken from when not given): the
    mean flow file is read only there (`lidarjax.io.load_field`), or None: all of it.

    `exact_points`: a function of the series field returning the points the series samples
    (absolute CFD metres), or None. The points are fixed when the mount is (the mean flow is
    sampled at the same points at every time), so an OpenFOAM or VTK mean flow is made
    exact there, the mesh's own cellPoint (`lidarjax.io.load_field`'s `exact_at`), as
    `lidarjax simulate` does; any other file is its own grid."""

    def frozen(mean):
        speed, direction = args.speed, args.direction
        if speed is None or direction is None:
            s, d = mean_wind_above(mean, location, float(heights[-1]))
            if not np.isfinite(s):
                top = np.asarray(location, np.float64) + np.array([0.0, 0.0, float(heights[-1])])
                raise ValueError(f"the mean flow is undefined above the lidar at {top.tolist()}; "
                                 "give --speed and --direction")
            speed = s if speed is None else float(speed)
            direction = d if direction is None else float(direction)
        if not speed > 0:
            raise ValueError(f"the advection speed must be positive, got {speed}")
        box = None
        if args.generate_box is None:
            parts = args.box.split(",")
            if len(parts) == 1:
                box = parts[0]
            elif len(parts) == 3:
                if args.box_shape is None:
                    raise ValueError("HAWC2 boxes need --box-shape nx,ny,nz (and --box-spacing)")
                box = parts
            else:
                raise ValueError(f"--box must be one .bts file or three files u,v,w; got {args.box!r}")
        return series_field(mean, location, speed=speed, direction=direction, box=box,
                            box_shape=args.box_shape, box_spacing=args.box_spacing,
                            generate_box=args.generate_box, length_scale=args.length_scale,
                            gamma=args.gamma, ti=args.ti, seed=args.seed, generator=args.generator)

    if args.field == "uniform":
        if args.speed is None or args.direction is None:
            raise ValueError("--field uniform needs --speed and --direction")
        return frozen(uniform(args.speed, args.direction))
    if exact_points is None:
        return frozen(load_field(args.field, region=region))
    # a mesh: the series field over its graded grid gives the points (its probe nodes follow
    # the box's and the grid's resolution); the box is built once, and the exact mean flow
    # then replaces the grid under it
    made = {}

    def at(grid):
        made["field"] = frozen(grid)
        return exact_points(made["field"][0])

    mean, report = load_field(args.field, region=region, exact_at=at, return_report=True)
    if not made:  # a gridded file: its own grid
        return frozen(mean)
    field, info = made["field"]
    return eqx.tree_at(lambda f: f.mean, field, mean), f"{info}; mean flow: {report.notes[-1]}"


def run_scanning(args, settings, beta, location, heights, start) -> int:
    """A scanning scan flown through the frozen-turbulence field (module docs)."""
    if args.ti <= 0:
        raise ValueError(f"--ti must be positive, got {args.ti}")
    pattern, gate, scan_file = read_scan_source(args, with_file=True)
    if args.probe == "auto":
        args.probe = "pulsed"
    probe = scanning_probe(args, gate)
    period = float(pattern.period)
    n_scans = args.scans or max(1, math.ceil(args.hours * 3600.0 / period - 1e-9))
    # a Halo file of repeated scans (rays a whole number of the header's scans): one VAD
    # profile per scan of the file, each with its own rays' angles
    per_scan = getattr(scan_file, "rays_per_scan", None)
    if not per_scan or pattern.n_rays % per_scan:
        per_scan = pattern.n_rays
    vad = pattern.kind in ("ppi", "vad") and per_scan >= 3  # a fit needs 3 rays
    files = ["series_scan.nc"] + ([] if args.no_plots else ["series_scan.png"]) + (
        ["series_vad.csv"] if vad else [])
    inputs = [("settings", args.settings), ("--field", None if args.field == "uniform"
                                                       else args.field),
              ("--scan", args.scan), ("--motion", args.motion)]
    inputs += [("--box", b) for b in (args.box.split(",") if args.box else ())]
    out = check_output_folder(args.out, files=files, inputs=inputs)
    mount = Mount(location, beta=beta, gamma=settings.gamma, psi=settings.psi,
                  epsilon=settings.epsilon)
    motion = read_motion_csv(args.motion) if args.motion else None
    # an OpenFOAM or VTK mean flow made exact at every point the scan samples (a fixed
    # mount samples the same points at every time; a moving one, the graded grid)
    region = None
    if motion is None:  # read only where the scan looks, and the advection's height above it
        lo, hi = scan_region(pattern, mount, probe)
        top = np.asarray(location, np.float64) + np.array([0.0, 0.0, float(heights[-1])])
        region = (np.minimum(lo, top), np.maximum(hi, top))
    field, info = build_field(args, settings, beta, location, heights, exact_points=None if motion else (
        lambda f: scan_points(f, pattern, mount, probe)), region=region)
    # probe nodes per gate, to size the batches only (16: typical of a count chosen for a box)
    nodes = 1 if isinstance(probe, PointProbe) else (args.probe_nodes or 16)
    per = args.chunk or max(1, SCAN_BATCH_SAMPLES
                            // (pattern.n_rays * pattern.n_sub * pattern.n_gates * nodes))
    per = min(per, n_scans)
    print(f"lidarjax series: {args.scan} ({pattern.kind}, {type(probe).__name__}), "
          f"{n_scans} scans of {period:g} s in batches of {per}; {info}")
    parts = []
    for first in range(0, n_scans, per):  # every batch `per` scans: one compilation
        res = simulate_scan_series(field, pattern, mount, n_scans=per, start=first * period,
                                   probe=probe, motion=motion)
        parts.append((np.asarray(res.los), np.asarray(res.times), np.asarray(res.flags)))
    los, times, flags = (np.concatenate(a)[:n_scans] for a in zip(*parts, strict=True))
    res = ScanResult(los=los, times=times, ranges=res.ranges, azimuth=res.azimuth,
                     elevation=res.elevation, directions=res.directions, points=res.points,
                     flags=flags)
    meta = {"settings": str(args.settings), "field": args.field, "scan": str(args.scan),
            "beta_deg": beta, "box": info, "start": str(start),
            "probe": type(probe).__name__}
    out.mkdir(parents=True, exist_ok=True)
    wrote = [write_scan_netcdf(out / "series_scan.nc", los, azimuth=res.azimuth,
                               elevation=res.elevation, ranges=res.ranges, ray_time=times,
                               flags=flags, title=f"lidarjax series {args.scan}", attrs=meta)]
    if vad:
        wrote.append(write_vad_csv(out / "series_vad.csv", res, meta, rays_per_scan=per_scan))
    if not args.no_plots:
        plot_scan(res, pattern.kind, out / "series_scan.png")
        wrote.append(out / "series_scan.png")
    print(f"{describe(res, pattern.kind)}")
    if pattern.kind in ("ppi", "vad") and not vad:
        print(f"no VAD profile: the scan has {per_scan} rays, a fit needs 3")
    print("wrote " + ", ".join(str(w) for w in wrote))
    return 0


def write_vad_csv(path, res, metadata, *, rays_per_scan: int | None = None):
    """The VAD wind profile of every scan of `res` (`lidarjax.scanning.vad_fit`, per gate) as
    a self-describing CSV (`lidarjax.io.write_table_csv`): one row per (scan, gate), the wind
    in the instrument's frame (``u`` towards its azimuth 90, ``v`` towards its azimuth 0,
    ``w`` up) and its meteorological direction there (where it comes from, clockwise from
    the instrument's azimuth 0). `rays_per_scan`: the pattern's rays are that many scans
    (a Halo file of repeated VADs), each fitted with its own rays; default all rays one
    scan."""
    los = np.asarray(res.los)
    reps, r, g = los.shape
    m = rays_per_scan if rays_per_scan and r % rays_per_scan == 0 else r
    n = reps * (r // m)
    los = los.reshape(n, m, g)
    az = np.broadcast_to(np.asarray(res.azimuth, np.float64).reshape(-1, m), (reps, r // m, m))
    el = np.broadcast_to(np.asarray(res.elevation, np.float64).reshape(-1, m), (reps, r // m, m))
    prof = vad_fit(los, az.reshape(n, m), el.reshape(n, m), res.ranges)
    vel = np.asarray(prof.velocity).reshape(n * g, 3)
    times = np.asarray(res.times).reshape(n, m)
    cols = {
        "scan": np.repeat(np.arange(n), g),
        "time": np.repeat(times.mean(axis=1), g),
        "range": np.tile(np.asarray(res.ranges), n),
        "height": np.tile(np.asarray(prof.heights), n),
        "u": vel[:, 0], "v": vel[:, 1], "w": vel[:, 2],
        "speed": np.asarray(prof.speed).ravel(),
        "direction": np.asarray(wind_direction(prof.velocity)).ravel(),
        "residual": np.asarray(prof.residual).ravel(),
        "n_rays": np.asarray(prof.n_rays).ravel(),
        "condition": np.asarray(prof.condition).ravel(),
        "flags": np.asarray(prof.flags).ravel(),
    }
    units = {"scan": "-", "time": "s since the start, mean of the scan's rays", "range": "m",
             "height": "m above the lidar", "u": "m/s", "v": "m/s", "w": "m/s",
             "speed": "m/s, horizontal", "direction": "deg, from, instrument frame",
             "residual": "m/s, rms", "n_rays": "-", "condition": "-",
             "flags": "lidarjax.InverseFlag bits"}
    return write_table_csv(path, cols, units, {**metadata, "profile": "lidarjax.scanning.vad_fit"})
