"""`lidarjax simulate`: the seed UDF's workflow, settings.dat + CFD runs -> seed output files.

The runs are `lidarjax.simulate_settings`, the files `lidarjax.write_seed_results` and the
NaN warning `lidarjax.explain_nans` (`lidarjax.workflows.seed_results`).

With a scanning ``--scan`` (a preset ``ppi``, ``rhi``, ``stare``, ``vad``, ``rosette`` or a
Halo ``.hpl`` / Windcube ``.nc`` scan file's layout) the lidar of the settings file (its
location per beta, gamma, psi, epsilon, with ``--pitch`` / ``--roll``) flies that scan in each
run instead (`lidarjax.scanning.simulate_scan`), each run read only over the box the scan's
sub-rays and probe cover (`lidarjax.cli._scanning.scan_region`); per beta it writes
``scan_<beta>.nc`` (CF NetCDF, time x beam x range) and with ``--plot`` ``scan_<beta>.png``.
"""

from __future__ import annotations

from .._util import format_number
from ..io import read_settings, write_scan_netcdf
from ..io.fields import check_field_file, load_field
from ..probe import PulsedProbe
from ..scanning import scan_points, simulate_scan
from ..workflows.seed_results import explain_nans, seed_result_files, write_seed_results
from ..workflows.seed_tables import settings_mount, simulate_settings, table_region
from ._common import (
    add_beta_arguments,
    add_command,
    add_run_arguments,
    add_settings_argument,
    add_tilt_arguments,
    check_output_folder,
    field_paths,
    make_probe,
    make_scan,
    selected_betas,
    warning_line,
)
from ._scanning import (
    add_scan_pattern_arguments,
    check_scan_options,
    describe,
    explain_scan_nans,
    plot_scan,
    read_scan_source,
    scan_choice,
    scan_region,
    scanning_probe,
)

_SEED_U_REF = (-15.0, 0.0, 0.0)


def register(sub) -> None:
    sim = add_command(
        sub, "simulate", run,
        "the seed workflow: settings.dat + CFD runs -> seed output files",
        "Simulate the lidar of a seed settings.dat in CFD runs (one per platform "
        "rotation beta) and write the seed's 'windcube simulation <beta> "
        "degrees.dat' files plus self-describing CSV tables.",
        epilog="examples:\n"
        "  lidarjax simulate settings.dat --field 'runs/platform_{beta}.npz' --all "
        "--scan windcube_v1 --out results/\n"
        "  lidarjax simulate settings.dat --field 'runs/platform_{beta}.npz' --all "
        "--scan ppi --elevation 2 --n-rays 72 --gates 60 --probe pulsed --plot "
        "--out ppi/\n"
        "  lidarjax simulate settings.dat --field run.npz --scan VAD_194.hpl --out vad/\n\n"
        "A scanning --scan (a preset or a .hpl / .nc scan file) writes per beta "
        "scan_<beta>.nc (CF NetCDF, time x beam x range: LOS, ray times, azimuth, "
        "elevation, flags) and, with --plot, scan_<beta>.png (a PPI on its cone seen "
        "from above, an RHI on its vertical plane) instead of the seed files; --probe "
        "pulsed is then the instrument's pulse per gate (--instrument, --gate-length).",
        raw=True)
    add_settings_argument(sim)
    add_beta_arguments(sim, beta_help="platform rotation to run (default: the settings file's "
                                      "beta)", all_help="run every beta row, one batch")
    add_run_arguments(sim, default_scan="windcube_v1", scan_type=scan_choice,
                      scan_help="a profiler (windcube_v1 default, windcube_v2, zephir), a "
                                "scanning preset (ppi, rhi, stare, vad, rosette) or a Halo "
                                ".hpl / Windcube .nc scan file (its rays, gates and times)")
    add_tilt_arguments(sim)
    sim.add_argument("--out", default=".", help="output folder (default: .)")
    sim.add_argument("--plot", action="store_true",
                     help="scanning scans: a PNG per beta of the scan on its cone or plane")
    add_scan_pattern_arguments(sim, title="scanning scans (a preset or a scan file)")


def run(args) -> int:
    scanning = check_scan_options(args, profiler_only=(
        ("--cone-angle", args.cone_angle is not None),
        ("--tilt-compensation", args.tilt_compensation),
        ("--u-ref (normalises the seed files)", tuple(args.u_ref) != _SEED_U_REF)))
    settings = read_settings(args.settings)
    betas = selected_betas(args, settings)
    for b in betas:
        settings.location(b)  # raises a ValueError naming the missing row
    paths = field_paths(args, betas)
    if scanning:
        return run_scanning(args, settings, betas, paths)
    scan = make_scan(args.scan, args.cone_angle, tilt_compensation=args.tilt_compensation)
    probe = make_probe(args)
    inputs = [("settings", args.settings)] + [(f"--field (beta {b:g})", p)
                                               for b, p in paths.items()]
    check_output_folder(args.out, files=seed_result_files(betas), inputs=inputs)
    fields = {}
    nodes = {}

    for path in paths.values():  # every file's format checked before computing
        check_field_file(path)

    def field_for(b, exact_at=None):
        # each run read only where its beams look, as `lidarjax table` reads it (a GridField
        # crop is bit-exact; an OpenFOAM or VTK mesh is resampled over that region only and
        # made exact, the mesh's own cellPoint, at the very points simulate samples: the
        # probe's nodes, chosen for the grid's resolution, of this beta's mount, given by
        # `simulate_settings` as `exact_at`)
        region = table_region(settings, [b], scan, probe=probe, pitch=args.pitch, roll=args.roll)
        field = load_field(paths[b], region=region, exact_at=exact_at)
        used = getattr(exact_at, "probe", None)
        if used is not None:
            nodes[b] = getattr(used, "node_counts", (used.n_nodes,))
        fields[b] = getattr(field, "grid", field)  # the grid explains NaNs by its extent
        return field

    sims = simulate_settings(settings, betas, field_for, scan, u_ref=args.u_ref, probe=probe,
                             pitch=args.pitch, roll=args.roll)
    write_seed_results(args.out, settings, sims, scan=args.scan, u_ref=args.u_ref,
                       sources={b: str(p) for b, p in paths.items()},
                       settings_file=args.settings, pitch=args.pitch, roll=args.roll, log=print)
    if nodes and isinstance(probe, PulsedProbe):  # the pulsed rule depends on the count only
        counts = " ".join(sorted({str(n) for c in nodes.values() for n in c}, key=int))
        graded = any(len(set(c)) > 1 for c in nodes.values())
        print(f"probe nodes per beam: {counts} (chosen for the CFD field's resolution"
              + (" along each height's beams; " if graded else "; ")
              + "`lidarjax monitor-points --probe pulsed --field` with the same --field writes "
              "the same nodes, every beta's own)")
    why = explain_nans(sims, fields, settings, paths)
    if why:
        warning_line("simulate", why)
    return 0


def run_scanning(args, settings, betas, paths) -> int:
    """A scanning scan per beta: the settings' mount (with --pitch, --roll), each CFD run read
    over the scan's region, one CF NetCDF (and with --plot one PNG) per beta."""
    pattern, gate = read_scan_source(args)
    probe = scanning_probe(args, gate)
    names = {b: f"scan_{format_number(b)}" for b in betas}
    files = [f"{n}.nc" for n in names.values()] + ([f"{n}.png" for n in names.values()]
                                                   if args.plot else [])
    inputs = ([("settings", args.settings), ("--scan", args.scan)]
              + [(f"--field (beta {b:g})", p) for b, p in paths.items()])
    out = check_output_folder(args.out, files=files, inputs=inputs)
    for path in paths.values():  # every file's format checked before computing
        check_field_file(path)
    mounts = settings_mount(settings, betas, pitch=args.pitch, roll=args.roll)
    out.mkdir(parents=True, exist_ok=True)
    for k, b in enumerate(betas):
        mount = mounts[k]
        # an OpenFOAM or VTK mesh: resampled over the scan's region and made exact (its own
        # cellPoint) at every node the scan samples, chosen for the grid's resolution
        field = load_field(paths[b], region=scan_region(pattern, mount, probe),
                           exact_at=lambda grid, m=mount: scan_points(grid, pattern, m, probe))
        res = simulate_scan(field, pattern, mount, probe=probe)
        nc = out / f"{names[b]}.nc"
        write_scan_netcdf(nc, res.los, azimuth=res.azimuth, elevation=res.elevation,
                          ranges=res.ranges, ray_time=res.times, flags=res.flags,
                          title=f"lidarjax simulate {args.scan}",
                          attrs={"settings": str(args.settings), "field": str(paths[b]),
                                 "scan": str(args.scan), "beta_deg": float(b),
                                 "pitch_deg": float(args.pitch), "roll_deg": float(args.roll),
                                 "probe": type(probe).__name__})
        wrote = [str(nc)]
        if args.plot:
            png = out / f"{names[b]}.png"
            plot_scan(res, pattern.kind, png)
            wrote.append(str(png))
        print(f"beta {b:g}: {describe(res, pattern.kind)}; wrote {', '.join(wrote)}")
        why = explain_scan_nans(res, field)
        if why:
            warning_line("simulate", f"beta {b:g}: {why}")
    return 0
