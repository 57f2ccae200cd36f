"""The `lidarjax` command line."""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np


def _enable_x64(args) -> None:
    import jax

    jax.config.update("jax_enable_x64", bool(args.x64))


def cmd_demo(args) -> int:
    from .demo import format_table, run_demo_simulations

    t0 = time.perf_counter()
    result, _ = run_demo_simulations()
    print("lidarjax demo: Windcube V1, V2 and ZephIR on a hemispherical platform (radius H = 20 m),")
    print("lidar 0.5 m above the deck, 12 inflow directions, free stream 10 m/s\n")
    print(format_table(result))
    print(f"\ndone in {time.perf_counter() - t0:.1f} s")
    return 0


def _add_probe_arguments(parser) -> None:
    parser.add_argument("--probe", choices=("point",), default="point",
                        help="probe volume (default: point)")


def _make_probe(args):
    return None


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

    from .io import read_settings, write_seed_output, write_table_csv
    from .io.fields import load_field
    from .io.seed_output import SEED_UNITS, format_number
    from .workflow import seed_columns, simulate_settings

    settings = read_settings(args.settings)
    if args.all:
        betas = [float(b) for b in settings.betas]
    else:
        betas = [float(settings.beta if args.beta is None else args.beta)]
    for b in betas:
        settings.location(b)  # raises a ValueError naming the missing row
    if len(betas) > 1 and "{beta}" not in args.field:
        raise ValueError(f"--field {args.field!r} must contain '{{beta}}' to name one CFD run "
                         "per platform rotation (e.g. 'runs/platform_{beta}.npz')")
    paths = {b: Path(args.field.format(beta=format_number(b))) for b in betas}
    missing = [str(p) for p in paths.values() if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"CFD field file(s) not found: {', '.join(missing)}")
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
        cff = cols["cff_U"]
        print(f"{b:7.1f} {path.name:<40s} {cols['U_mag_lidar'][-1]:13.3f} "
              f"{np.nanmin(cff):8.4f}..{np.nanmax(cff):8.4f}")
    print(f"wrote {len(sims)} seed file(s) and CSV table(s) to {out}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lidarjax",
        description="Simulate wind lidars in CFD fields and correct their records.",
    )
    parser.add_argument("--x64", action=argparse.BooleanOptionalAction, default=True,
                        help="compute in float64 (default) or float32 (--no-x64)")
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run the built-in platform scene, no input files",
                          description="Run the built-in hemisphere 'platform' scene.",
                          epilog="example: lidarjax demo")
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
    sim.add_argument("--field", required=True,
                     help="CFD field file (.npz, .nc or Fluent ASCII); '{beta}' is replaced "
                          "by each platform rotation, e.g. 'runs/platform_{beta}.npz'")
    which = sim.add_mutually_exclusive_group()
    which.add_argument("--beta", type=float, help="platform rotation to run (default: the "
                                                 "settings file's beta)")
    which.add_argument("--all", action="store_true", help="run every beta row, one batch")
    sim.add_argument("--scan", choices=SCAN_CHOICES, default="windcube_v1")
    sim.add_argument("--cone-angle", type=float, default=None,
                     help="cone angle in degrees (default: the scan's, 30 / 28 / 30)")
    sim.add_argument("--u-ref", type=_vector, default=(-15.0, 0.0, 0.0),
                     help="free stream u,v,w in the CFD frame, m/s (default: the seed "
                          "UDF's -15,0,0)")
    _add_probe_arguments(sim)
    sim.add_argument("--out", default=".", help="output folder (default: .)")
    sim.set_defaults(func=cmd_simulate)
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
