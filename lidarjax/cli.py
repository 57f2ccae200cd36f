"""The `lidarjax` command line."""

from __future__ import annotations

import argparse
import sys

import numpy as np


def _enable_x64(args) -> None:
    import jax

    jax.config.update("jax_enable_x64", bool(args.x64))


def cmd_demo(args) -> int:
    import json
    from pathlib import Path

    from .demo import run_demo

    out = Path(args.out)
    print("lidarjax demo: Windcube V1, V2 (pulsed probe) and ZephIR (CW probe) on a "
          "hemispherical platform\n(H = 20 m, lidar 0.5 m above the deck, seed free stream "
          "15 m/s, 12 platform rotations)\n")
    summary = run_demo(out, plots=not args.no_plots)
    print()
    print(summary["table"])
    r = summary["records"]
    print(f"\nsynthetic records ({r['n_records']} x {r['heights']} heights, LOS noise 0.1 m/s): "
          f"speed bias {r['speed_bias_uncorrected']:+.3f} m/s and rms error "
          f"{r['speed_rms_uncorrected']:.3f} m/s uncorrected -> bias "
          f"{r['speed_bias_corrected']:+.3f} m/s, rms {r['speed_rms_corrected']:.3f} m/s "
          f"corrected (the rms floor is the noise); direction mean error "
          f"{r['direction_mae_uncorrected']:.2f} -> {r['direction_mae_corrected']:.2f} deg; "
          f"{100 * r['converged_fraction']:.1f} % converged")
    (out / "summary.json").write_text(json.dumps({k: v for k, v in summary.items()
                                                  if k != "table"}, indent=2))
    print(f"\nall outputs in {out}/ ; done in {summary['seconds']:.1f} s")
    return 0


def _add_run_arguments(parser, *, default_scan: str) -> None:
    """CFD runs, scan, free stream and probe: shared by `simulate` and `table`."""
    parser.add_argument("--field", required=True,
                        help="CFD field file (.npz, .nc or Fluent ASCII); '{beta}' is replaced "
                             "by each platform rotation, e.g. 'runs/platform_{beta}.npz'")
    parser.add_argument("--scan", choices=SCAN_CHOICES, default=default_scan)
    parser.add_argument("--cone-angle", type=float, default=None,
                        help="cone angle in degrees (default: the scan's, 30 / 28 / 30)")
    parser.add_argument("--u-ref", type=_vector, default=(-15.0, 0.0, 0.0),
                        help="free stream u,v,w in the CFD frame, m/s (default: the seed "
                             "UDF's -15,0,0)")
    _add_probe_arguments(parser)


def _add_probe_arguments(parser) -> None:
    parser.add_argument("--probe", choices=("point", "pulsed", "cw"), default="point",
                        help="probe volume: point (default), pulsed (Windcube: Gaussian pulse * "
                             "range gate) or cw (ZephIR: Lorentzian)")
    parser.add_argument("--probe-nodes", type=int, default=None,
                        help="quadrature nodes along the beam (default 9 pulsed, 17 cw)")
    parser.add_argument("--probe-scale", type=float, default=1.0,
                        help="model scale s of the CFD (1:s); probe lengths are divided by s "
                             "(e.g. 100 for a 1:100 wind-tunnel-scale platform)")


def _make_probe(args):
    from .probe import CWProbe, PulsedProbe

    if args.probe_scale <= 0:
        raise ValueError(f"--probe-scale must be positive, got {args.probe_scale}")
    if args.probe_nodes is not None and args.probe_nodes < 1:
        raise ValueError(f"--probe-nodes must be at least 1, got {args.probe_nodes}")
    if args.probe == "point":
        return None
    kind = PulsedProbe if args.probe == "pulsed" else CWProbe
    probe = kind() if args.probe_nodes is None else kind(n_nodes=args.probe_nodes)
    return probe.scaled(args.probe_scale) if args.probe_scale != 1.0 else probe


SCAN_CHOICES = ("windcube_v1", "windcube_v2", "zephir")


def _vector(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers 'u,v,w', got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three numbers 'u,v,w', got {text!r}")
    return values


def _make_scan(name: str, cone: float | None):
    from . import scan as scans

    make = getattr(scans, name)
    return make() if cone is None else make(cone)


def cmd_simulate(args) -> int:
    from pathlib import Path

    from .io import read_settings, write_netcdf, write_seed_output, write_table_csv
    from .io._common import have_module
    from .io.fields import load_field
    from .io.seed_output import SEED_UNITS, format_number
    from .workflow import seed_columns, simulate_settings

    settings = read_settings(args.settings)
    betas = _betas(args, settings)
    for b in betas:
        settings.location(b)  # raises a ValueError naming the missing row
    paths = _field_paths(args, betas)
    scan = _make_scan(args.scan, args.cone_angle)
    probe = _make_probe(args)
    sims = simulate_settings(settings, betas, lambda b: load_field(paths[b]), scan,
                             u_ref=args.u_ref, probe=probe)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    print(f"{'beta':>7s} {'file':<40s} {'U_lidar(top)':>13s} {'cff_U range':>18s}")
    for b, sim in sims.items():
        cols = seed_columns(sim)
        path = write_seed_output(out, b, cols, verbose=settings.verbose)
        meta = {"settings": str(args.settings), "field": str(paths[b]), "scan": args.scan,
                "beta_deg": b, "gamma_deg": settings.gamma, "psi_deg": settings.psi,
                "epsilon_deg": settings.epsilon, "u_ref_cfd_m_s": ",".join(map(str, args.u_ref)),
                "directions": "Th_lidar/th_point: seed azimuth = (-atan2(v,u)) mod 360; "
                              "meteorological = (seed + 270) mod 360"}
        write_table_csv(out / f"simulation_{format_number(b)}.csv", cols, SEED_UNITS, meta)
        if have_module("xarray"):
            write_netcdf(out / f"simulation_{format_number(b)}.nc", cols, meta)
        cff = cols["cff_U"]
        print(f"{b:7.1f} {path.name:<40s} {cols['U_mag_lidar'][-1]:13.3f} "
              f"{np.nanmin(cff):8.4f}..{np.nanmax(cff):8.4f}")
    extra = " and NetCDF" if have_module("xarray") else ""
    print(f"wrote {len(sims)} seed file(s), CSV{extra} table(s) to {out}")
    return 0


def _betas(args, settings) -> list[float]:
    if getattr(args, "all", False):
        return [float(b) for b in settings.betas]
    return [float(settings.beta if args.beta is None else args.beta)]


def _field_paths(args, betas):
    from pathlib import Path

    from .io.seed_output import format_number

    if len(betas) > 1 and "{beta}" not in args.field:
        raise ValueError(f"--field {args.field!r} must contain '{{beta}}' to name one CFD run "
                         "per platform rotation (e.g. 'runs/platform_{beta}.npz')")
    paths = {b: Path(args.field.format(beta=format_number(b))) for b in betas}
    missing = [str(p) for p in paths.values() if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"CFD field file(s) not found: {', '.join(missing)}")
    return paths


def cmd_table(args) -> int:
    from pathlib import Path

    from .io import read_settings, save_table
    from .io.fields import load_field
    from .workflow import build_table

    settings = read_settings(args.settings)
    betas = [float(b) for b in settings.betas]
    paths = _field_paths(args, betas)
    scan = _make_scan(args.scan, args.cone_angle)
    probe = _make_probe(args)
    out = Path(args.out)
    if not out.parent.is_dir():
        raise FileNotFoundError(f"output folder not found: {out.parent}")
    table, _ = build_table(settings, betas, lambda b: load_field(paths[b]), scan,
                           u_ref=args.u_ref, probe=probe)
    meta = {"settings": str(args.settings), "field": args.field, "scan": args.scan,
            "cone_angle_deg": float(scan.cone_angle), "probe": args.probe,
            "gamma_deg": settings.gamma, "psi_deg": settings.psi,
            "epsilon_deg": settings.epsilon, "u_ref_cfd_m_s": list(args.u_ref)}
    save_table(out, table, meta)
    print(f"response table: {table.n_directions} directions x {table.n_heights} heights x "
          f"{table.n_beams} beams -> {out}")
    return 0


def cmd_correct(args) -> int:
    from pathlib import Path

    from .io import load_table
    from .workflow import correct_records, write_corrected_csv

    table, meta = load_table(args.table, return_metadata=True)
    records = Path(args.records)
    if not records.is_file():
        raise FileNotFoundError(f"record file not found: {records}")
    out = Path(args.out) if args.out else records.with_name(records.stem + "_corrected.csv")
    if not out.parent.is_dir():
        raise FileNotFoundError(f"output folder not found: {out.parent}")
    result = correct_records(table, records, noise=args.noise, progress=not args.quiet)
    write_corrected_csv(out, result, {"records": str(records), "table": str(args.table),
                                      "scan": meta.get("scan", "?")})
    ok = np.asarray(result.converged)
    du = np.nanmedian(np.abs(result.speed - result.measured_speed))
    print(f"corrected {ok.sum()} of {ok.size} record-heights ({len(result.time)} records x "
          f"{len(result.heights)} heights); median |correction| {du:.3f} m/s -> {out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lidarjax",
        description="Simulate wind lidars in CFD fields and correct their records.",
    )
    parser.add_argument("--x64", action=argparse.BooleanOptionalAction, default=True,
                        help="compute in float64 (default) or float32 (--no-x64)")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser(
        "demo", help="run the whole job on the built-in platform scene, no input files",
        description="Simulate Windcube V1/V2 and ZephIR on the built-in hemisphere 'platform' "
                    "(12 platform rotations), write seed files, a response table, a month of "
                    "synthetic .sta records and their correction, and the figures.",
        epilog="example: lidarjax demo --out lidarjax-demo")
    demo.add_argument("--out", default="lidarjax-demo", help="output folder (default: "
                                                             "lidarjax-demo)")
    demo.add_argument("--no-plots", action="store_true", help="skip the figures")
    demo.set_defaults(func=cmd_demo)

    sim = sub.add_parser(
        "simulate", help="the seed workflow: settings.dat + CFD runs -> seed output files",
        description="Simulate the lidar of a seed settings.dat in CFD runs (one per platform "
                    "rotation beta) and write the seed's 'windcube simulation <beta> "
                    "degrees.dat' files plus self-describing CSV tables.",
        epilog="example: lidarjax simulate settings.dat --field 'runs/platform_{beta}.npz' "
               "--all --scan windcube_v1 --out results/",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    sim.add_argument("settings", help="the seed's settings.dat")
    which = sim.add_mutually_exclusive_group()
    which.add_argument("--beta", type=float, help="platform rotation to run (default: the "
                                                 "settings file's beta)")
    which.add_argument("--all", action="store_true", help="run every beta row, one batch")
    _add_run_arguments(sim, default_scan="windcube_v1")
    sim.add_argument("--out", default=".", help="output folder (default: .)")
    sim.set_defaults(func=cmd_simulate)

    tab = sub.add_parser(
        "table", help="build a response table (for `correct`) from CFD runs over directions",
        description="Simulate the lidar of a seed settings.dat in every CFD run (one per "
                    "platform rotation beta, i.e. per inflow direction) and save the LOS "
                    "per unit free-stream speed as a response table (.npz).",
        epilog="example: lidarjax table settings.dat --field 'runs/platform_{beta}.npz' "
               "--scan windcube_v2 --out site_table.npz")
    tab.add_argument("settings", help="the seed's settings.dat (all beta rows are used)")
    _add_run_arguments(tab, default_scan="windcube_v2")
    tab.add_argument("--out", required=True, help="table file to write (.npz)")
    tab.set_defaults(func=cmd_table)

    cor = sub.add_parser(
        "correct", help="invert lidar records for the free-stream wind with a response table",
        description="Read Windcube .sta/.rtd or ZephIR .csv records, invert every record and "
                    "height with the table, and write corrected speed, direction, "
                    "uncertainty and flags as CSV (written atomically).",
        epilog="example: lidarjax correct --table site_table.npz --records "
               "wls7_2020_10_07.sta --out corrected.csv")
    cor.add_argument("--table", required=True, help="response table from `lidarjax table`")
    cor.add_argument("--records", required=True, help=".sta, .stdsta, .rtd or ZephIR .csv")
    cor.add_argument("--out", default=None, help="output CSV (default: <records>_corrected.csv)")
    cor.add_argument("--noise", type=float, default=None,
                     help="noise standard deviation (m/s) for the uncertainties (default: "
                          "estimated from spare beams; needed for .sta/.csv)")
    cor.add_argument("--quiet", action="store_true", help="no progress bar")
    cor.set_defaults(func=cmd_correct)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    _enable_x64(args)
    try:
        return args.func(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"lidarjax {args.command}: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
