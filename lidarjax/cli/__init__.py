"""The `lidarjax` command line: one module per command, each with `register(sub)` (its
argparse sub-parser) and `run(args)` (returns the exit code).

Every command validates its inputs before computing and turns user errors into one line on
stderr and exit code 2 (`ValueError`, `FileNotFoundError`; a missing input file or folder is
named when the arguments are parsed); Ctrl-C gives one line and 130. Warnings are one line
each, ``lidarjax COMMAND: warning: ...`` (`one_line_warnings`).
"""

from __future__ import annotations

import argparse
import sys

from .. import __version__
from . import calibrate as calibrate_cmd
from . import correct, demo, design, farm, lac, monitor_points, scan, series, simulate, table
from . import sensitivity as sensitivity_cmd
from ._common import (
    OneLineParser,
    Terminated,
    enable_x64,
    install_signal_handlers,
    one_line_warnings,
    setup_compilation_cache,
)

#: The command modules, in the order `--help` lists them.
COMMANDS = (demo, simulate, table, correct, calibrate_cmd, monitor_points, sensitivity_cmd, series,
            farm, scan, design, lac)


def build_parser() -> argparse.ArgumentParser:
    parser = OneLineParser(
        prog="lidarjax",
        description="Simulate wind lidars in CFD fields and correct their records.",
    )
    parser.add_argument("--version", action="version", version=f"lidarjax {__version__}",
                        help="print the version (lidarjax.__version__, the installed package's) and exit")
    parser.add_argument("--x64", action=argparse.BooleanOptionalAction, default=True,
                        help="compute in float64 (default) or float32 (--no-x64)")
    parser.add_argument("--no-cache", action="store_true",
                        help="do not use the persistent compilation cache (default: on, in "
                             "$XDG_CACHE_HOME/lidarjax/jax; also off with LIDARJAX_NO_CACHE=1)")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS:
        command.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as done:  # usage error (one line, exit 2) or --help (exit 0)
        return int(done.code or 0)
    enable_x64(args)
    setup_compilation_cache(args)
    restore = install_signal_handlers()
    try:
        with one_line_warnings(args.command):
            return args.func(args)
    except (ValueError, FileNotFoundError) as err:
        print(f"lidarjax {args.command}: error: {err}", file=sys.stderr)
        return 2
    except (OSError, ImportError) as err:  # permissions, full disk, a missing optional extra
        print(f"lidarjax {args.command}: error: {err}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"\nlidarjax {args.command}: interrupted; no output file was left half-written",
              file=sys.stderr)
        return 130
    except Terminated:
        print(f"lidarjax {args.command}: terminated; no output file was left half-written",
              file=sys.stderr)
        return 143
    finally:
        restore()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
