"""Arguments and helpers shared by the `lidarjax` commands."""

from __future__ import annotations

import argparse

SCAN_CHOICES = ("windcube_v1", "windcube_v2", "zephir")


def enable_x64(args) -> None:
    import jax

    jax.config.update("jax_enable_x64", bool(args.x64))


def add_run_arguments(parser, *, default_scan: str) -> None:
    """CFD runs, scan, free stream and probe: shared by `simulate` and `table`."""
    parser.add_argument("--field", required=True,
                        help="CFD field file (.npz, .nc or Fluent ASCII); '{beta}' is replaced "
                             "by each platform rotation, e.g. 'runs/platform_{beta}.npz'")
    parser.add_argument("--scan", choices=SCAN_CHOICES, default=default_scan)
    parser.add_argument("--cone-angle", type=float, default=None,
                        help="cone angle in degrees (default: the scan's, 30 / 28 / 30)")
    parser.add_argument("--u-ref", type=vector, default=(-15.0, 0.0, 0.0),
                        help="free stream u,v,w in the CFD frame, m/s (default: the seed "
                             "UDF's -15,0,0)")
    add_probe_arguments(parser)


def add_probe_arguments(parser) -> None:
    parser.add_argument("--probe", choices=("point", "pulsed", "cw"), default="point",
                        help="probe volume: point (default), pulsed (Windcube: Gaussian pulse * "
                             "range gate) or cw (ZephIR: Lorentzian)")
    parser.add_argument("--probe-nodes", type=int, default=None,
                        help="quadrature nodes along the beam (default 9 pulsed, 17 cw)")
    parser.add_argument("--probe-scale", type=float, default=1.0,
                        help="model scale s of the CFD (1:s); probe lengths are divided by s "
                             "(e.g. 100 for a 1:100 wind-tunnel-scale platform)")


def make_probe(args):
    from ..probe import CWProbe, PulsedProbe

    if args.probe_scale <= 0:
        raise ValueError(f"--probe-scale must be positive, got {args.probe_scale}")
    if args.probe_nodes is not None and args.probe_nodes < 1:
        raise ValueError(f"--probe-nodes must be at least 1, got {args.probe_nodes}")
    if args.probe == "point":
        return None
    kind = PulsedProbe if args.probe == "pulsed" else CWProbe
    probe = kind() if args.probe_nodes is None else kind(n_nodes=args.probe_nodes)
    return probe.scaled(args.probe_scale) if args.probe_scale != 1.0 else probe


def vector(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers 'u,v,w', got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three numbers 'u,v,w', got {text!r}")
    return values


def make_scan(name: str, cone: float | None):
    from .. import scan as scans

    make = getattr(scans, name)
    return make() if cone is None else make(cone)


def selected_betas(args, settings) -> list[float]:
    if getattr(args, "all", False):
        return [float(b) for b in settings.betas]
    return [float(settings.beta if args.beta is None else args.beta)]


def field_paths(args, betas):
    from pathlib import Path

    from ..io.seed_output import format_number

    if len(betas) > 1 and "{beta}" not in args.field:
        raise ValueError(f"--field {args.field!r} must contain '{{beta}}' to name one CFD run "
                         "per platform rotation (e.g. 'runs/platform_{beta}.npz')")
    paths = {b: Path(args.field.format(beta=format_number(b))) for b in betas}
    missing = [str(p) for p in paths.values() if not p.is_file()]
    if missing:
        raise FileNotFoundError(f"CFD field file(s) not found: {', '.join(missing)}")
    return paths
