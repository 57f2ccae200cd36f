"""The `lidarjax` command line."""

from __future__ import annotations

import argparse
import sys
import time


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
