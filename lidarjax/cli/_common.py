"""Arguments and helpers shared by the `lidarjax` commands.

Besides the shared arguments this module holds the command line's file discipline:

- `check_output_file` / `check_output_folder`: called by every command *before* it computes
  anything. An output may not be one of the command's inputs (paths are compared after
  resolving symbolic links, and by inode when both exist); its folder must exist and accept
  a new file (checked by creating and removing a probe file, which also catches read-only
  file systems when running as root); an output file may not be a folder, and an existing
  output is replaced only if it is a regular, writable file. Replacing is atomic (a
  temporary file beside it, then `os.replace`), so the previous version survives until the
  new one is complete.
- `install_signal_handlers`: SIGTERM raises `Terminated` (a `BaseException`) so that the
  atomic writers remove their temporary file on the way out.
- `setup_compilation_cache`: JAX's persistent compilation cache in a user folder.
- argparse types that validate numbers (finite, positive) at parse time.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import signal
import string
import sys
import tempfile
import threading
import warnings
from pathlib import Path

import jax
import numpy as np

from .. import scan as scans
from .._util import format_number, nan_mean
from ..io.openfoam import is_openfoam_case
from ..probe import CWProbe, PulsedProbe
from ..workflows.records import DEFAULT_MIN_AVAILABILITY

SCAN_CHOICES = ("windcube_v1", "windcube_v2", "zephir")


def enable_x64(args) -> None:
    jax.config.update("jax_enable_x64", bool(args.x64))


class OneLineParser(argparse.ArgumentParser):
    """An `ArgumentParser` whose usage errors are one line on stderr (exit 2)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def add_command(sub, name: str, run, help: str, description: str, *, epilog: str | None = None,
                raw: bool = False, aliases=()) -> argparse.ArgumentParser:
    """One command's sub-parser: `name` (and `aliases`) with its one-line `help`, its
    `description` and `epilog` (`raw`: printed as written, line breaks kept), running
    ``run(args)``. Returns the parser, for the command's arguments."""
    kw = {"formatter_class": argparse.RawDescriptionHelpFormatter} if raw else {}
    parser = sub.add_parser(name, help=help, description=description, epilog=epilog,
                            aliases=list(aliases), **kw)
    parser.set_defaults(func=run)
    return parser


class Terminated(BaseException):  # noqa: N818 - named like KeyboardInterrupt
    """Raised in the main thread when the process receives SIGTERM."""


def install_signal_handlers():
    """SIGTERM -> `Terminated`, so `finally` blocks and atomic writers clean up.

    Returns a function that restores the previous handler (the command line calls it on
    the way out, so an in-process caller keeps its own handler)."""
    if threading.current_thread() is not threading.main_thread():
        return lambda: None

    def _terminate(signum, frame):
        raise Terminated(signum)

    previous = signal.signal(signal.SIGTERM, _terminate)
    return lambda: signal.signal(signal.SIGTERM, previous)


def status_line(command: str, text) -> None:
    """Print `text` on stderr as one line of the command: ``lidarjax COMMAND: ...``."""
    print(f"lidarjax {command}: {text}", file=sys.stderr)


def warning_line(command: str, text) -> None:
    """Print `text` as the command's one-line warning on stderr: ``lidarjax COMMAND: warning:
    ...`` (line breaks and runs of spaces in `text` become single spaces)."""
    status_line(command, f"warning: {' '.join(str(text).split())}")


@contextlib.contextmanager
def one_line_warnings(command: str):
    """While the command runs, every Python warning that is shown (the filters decide which,
    as always) is printed by `warning_line`: one line, without the source file, line number
    and source line Python adds. Restored on the way out: the library's warnings stay proper
    `UserWarning` instances for other callers."""

    def show(message, category, filename, lineno, file=None, line=None):
        warning_line(command, message)

    with warnings.catch_warnings():
        warnings.showwarning = show
        yield


def print_height_means(heights, columns: dict, *, what: str = "record") -> None:
    """A table of per-height means over records: `columns` maps a header to ``(values (r, h),
    width, decimals)``. A mean with no value behind it (no records, or all NaN at that
    height) prints ``nan``, and one line after the table says why, never numpy's warning."""
    print(f"{'height':>7s} " + " ".join(f"{name:>{w}s}" for name, (_, w, _) in columns.items()))
    means = {name: nan_mean(np.asarray(v, np.float64).reshape(-1, len(heights)), axis=0)
             for name, (v, _, _) in columns.items()}
    for k, h in enumerate(heights):
        print(f"{h:7.1f} " + " ".join(f"{means[name][k]:{w}.{d}f}"
                                      for name, (_, w, d) in columns.items()))
    empty = [name for name, m in means.items() if np.isnan(m).any()]
    if empty:
        print(f"nan: no finite {what} behind the mean ({', '.join(empty)}; no {what}s, or every "
              f"one NaN at that height: see its flags)")


def cache_folder() -> Path:
    """The persistent compilation cache folder: ``$XDG_CACHE_HOME/lidarjax/jax`` (default
    ``~/.cache/lidarjax/jax``)."""
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "lidarjax" / "jax"


def setup_compilation_cache(args) -> Path | None:
    """Turn on JAX's persistent compilation cache for this command-line process.

    Off with ``--no-cache`` or the environment variable ``LIDARJAX_NO_CACHE=1``. Only the
    command line does this; importing `lidarjax` never changes JAX's configuration. A folder
    that cannot be created just means no cache (never an error). Returns the folder or None.
    """
    if getattr(args, "no_cache", False) or os.environ.get("LIDARJAX_NO_CACHE", "") not in ("",
                                                                                          "0"):
        return None
    folder = cache_folder()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None

    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return folder


# ------------------------------------------------------------------------------------------
# numbers


def _parsed(text: str, convert, expected: str):
    """``convert(text)``, or `argparse.ArgumentTypeError` saying what was `expected`."""
    try:
        return convert(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {expected}, got {text!r}") from None


def finite_float(text: str) -> float:
    """argparse type: a finite float."""
    value = _parsed(text, float, "a number")
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"expected a finite number, got {text!r}")
    return value


def positive_float(text: str) -> float:
    """argparse type: a finite float > 0."""
    value = finite_float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"expected a positive number, got {text!r}")
    return value


def positive_int(text: str) -> int:
    """argparse type: an integer >= 1."""
    value = _parsed(text, int, "a positive integer")
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def percentage(text: str) -> float:
    """argparse type: a percentage in [0, 100]."""
    value = finite_float(text)
    if not 0.0 <= value <= 100.0:
        raise argparse.ArgumentTypeError(f"expected a percentage in [0, 100], got {text!r}")
    return value


def tilt_angle(text: str) -> float:
    """argparse type: a finite angle in [-90, 90] degrees."""
    value = finite_float(text)
    if not -90.0 <= value <= 90.0:
        raise argparse.ArgumentTypeError(f"expected an angle in [-90, 90] degrees, got {text!r}")
    return value


def height_list(text: str) -> tuple[float, ...]:
    """argparse type: comma-separated heights in metres, finite, positive, increasing."""
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(",") if v != "")
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"expected heights in metres separated by commas (e.g. 40,54,74), got {text!r}"
        ) from None
    if not values:
        raise argparse.ArgumentTypeError(f"expected at least one height, got {text!r}")
    if not all(math.isfinite(v) and v > 0 for v in values):
        raise argparse.ArgumentTypeError(f"heights must be finite and > 0 m, got {text!r}")
    if any(b <= a for a, b in zip(values, values[1:], strict=False)):
        raise argparse.ArgumentTypeError(f"heights must be strictly increasing, got {text!r}")
    return values


# ------------------------------------------------------------------------------------------
# input paths: argparse types, so that a missing input is named at parse time (one line,
# exit 2), before anything is read or compiled


def _input(text: str, what: str, *, folder: bool | None) -> str:
    """`text` if it names an existing input (`folder`: True a folder, False a file, None
    either), else `argparse.ArgumentTypeError` naming it and what it should be."""
    path = Path(text)
    if not path.exists():
        raise argparse.ArgumentTypeError(f"{what} not found: {text}")
    if folder is False and path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a folder; expected a {what}")
    if folder is True and not path.is_dir():
        raise argparse.ArgumentTypeError(f"{text} is a file; expected a {what}")
    return text


def input_file(text: str) -> str:
    """argparse type: an existing file the command reads."""
    return _input(text, "file", folder=False)


def input_folder(text: str) -> str:
    """argparse type: an existing folder the command reads."""
    return _input(text, "folder", folder=True)


def input_path(text: str) -> str:
    """argparse type: an existing file or folder the command reads (a case folder or its
    file, a probes folder or its output file)."""
    return _input(text, "file or folder", folder=None)


def input_case(text: str) -> str:
    """argparse type: an existing OpenFOAM case (its folder, a time folder in it, or its
    ``.foam`` / ``controlDict`` file)."""
    return _input(text, "OpenFOAM case", folder=None)


def field_input(text: str) -> str:
    """argparse type of ``--field``: an existing CFD field file or mesh folder, or a pattern
    with a ``{...}`` placeholder (each platform rotation's file is checked by `field_paths`
    once the rotations are known, still before anything is read)."""
    return text if "{" in text else _input(text, "CFD field file or folder", folder=None)


def input_files(text: str) -> str:
    """argparse type: one existing file, or several separated by commas (e.g. a HAWC2 box's
    ``u.bin,v.bin,w.bin``); each is checked."""
    for part in text.split(","):
        if part:
            _input(part, "file", folder=False)
    return text


# ------------------------------------------------------------------------------------------
# files


def _same_path(a: Path, b: Path) -> bool:
    try:
        if a.exists() and b.exists():
            return os.path.samefile(a, b)
    except OSError:
        pass
    return a.resolve() == b.resolve()


def _refuse_inputs(out: Path, inputs, option: str) -> None:
    for name, path in inputs:
        if path is not None and _same_path(out, Path(path)):
            raise ValueError(f"{option} {out} is the same file as the input {name} {path}; "
                             "choose another output path (inputs are never overwritten)")


def _probe_folder(folder: Path, option: str) -> None:
    if not folder.exists():
        raise FileNotFoundError(f"{option}: output folder not found: {folder}")
    if not folder.is_dir():
        raise ValueError(f"{option}: {folder} is not a folder")
    try:
        fd, name = tempfile.mkstemp(prefix=".lidarjax-write-test-", dir=folder)
    except OSError as err:
        raise ValueError(f"{option}: cannot write into the folder {folder} "
                         f"({err.strerror or err}); choose a writable folder") from None
    os.close(fd)
    os.unlink(name)


def check_output_file(path, *, inputs=(), option: str = "--out") -> Path:
    """Check before computing that `path` can be written as a new or replaced file.

    `inputs` is a sequence of ``(name, path)`` the command reads. Raises `ValueError` (or
    `FileNotFoundError` for a missing folder) with one line naming the fix.
    """
    out = Path(path)
    if str(path).endswith(os.sep) or out.is_dir():
        raise ValueError(f"{option} {path} is a folder; give a file name, e.g. "
                         f"{out / 'output'}")
    _refuse_inputs(out, inputs, option)
    if out.exists() or out.is_symlink():
        if not out.is_file():
            raise ValueError(f"{option} {out} exists and is not a regular file; choose "
                             "another output path")
        if not os.access(out, os.W_OK) or not (out.stat().st_mode & 0o222):
            raise ValueError(f"{option} {out} exists and is read-only; remove it or choose "
                             "another output path")
    _probe_folder(out.parent if str(out.parent) else Path("."), option)
    return out


def check_output_folder(path, *, files=(), inputs=(), option: str = "--out") -> Path:
    """Check before computing that the folder `path` can be created or written, and that
    none of the file names `files` written inside it is an input or a folder."""
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{option} {out} is an existing file, not a folder; give a folder "
                         "name (it is created when missing)")
    parent = out
    while not parent.exists():
        parent = parent.parent if str(parent.parent) != str(parent) else Path(".")
        if str(parent) in ("", "."):
            parent = Path(".")
            break
    if not parent.is_dir():
        raise ValueError(f"{option} {out}: {parent} is a file, so the folder cannot be created")
    _probe_folder(parent, option)
    for name in files:
        check = out / name
        _refuse_inputs(check, inputs, option)
        if check.is_dir():
            raise ValueError(f"{option}: {check} is a folder, expected an output file name "
                             "there; move it away")
    return out


def add_record_arguments(parser, *, records: dict, table: str = "", used: str = "not "
                         "used") -> None:
    """The inputs of `correct` and `calibrate`: ``--table`` (a table from `lidarjax table`;
    `table`: more about it), ``--records`` (`records`: the keywords of its argument, e.g. its
    help) and ``--min-availability`` (`used`: what happens to records below it)."""
    parser.add_argument("--table", required=True, type=input_file,
                        help="response table from `lidarjax table`" + (f" ({table})" if table
                                                                         else ""))
    parser.add_argument("--records", required=True, type=input_file, **records)
    parser.add_argument("--min-availability", type=percentage,
                        default=DEFAULT_MIN_AVAILABILITY,
                        help=f"records below this data availability (percent) are {used} "
                             f"(default {DEFAULT_MIN_AVAILABILITY:g})")


def add_settings_argument(parser, detail: str = "") -> None:
    """The seed's settings.dat, the positional input of the commands that read one (an
    existing file, checked at parse time); `detail` follows in the help."""
    parser.add_argument("settings", type=input_file,
                        help="the seed's settings.dat" + (f" ({detail})" if detail else ""))


def add_beta_arguments(parser, *, beta_help: str, all_help: str) -> None:
    """--beta (one platform rotation, default the settings file's) or --all (every row)."""
    which = parser.add_mutually_exclusive_group()
    which.add_argument("--beta", type=finite_float, help=beta_help)
    which.add_argument("--all", action="store_true", help=all_help)


def add_run_arguments(parser, *, default_scan: str, scan_type=None, scan_help=None) -> None:
    """CFD runs, scan, free stream and probe: shared by `simulate` and `table` (`scan_type`:
    an argparse type for ``--scan`` instead of the profilers' choices)."""
    parser.add_argument("--field", required=True, type=field_input,
                        help="CFD field file (.npz, .nc or Fluent ASCII); '{beta}' is replaced "
                             "by each platform rotation, e.g. 'runs/platform_{beta}.npz'")
    if scan_type is None:
        parser.add_argument("--scan", choices=SCAN_CHOICES, default=default_scan)
    else:
        parser.add_argument("--scan", type=scan_type, default=default_scan, help=scan_help)
    parser.add_argument("--cone-angle", type=positive_float, default=None,
                        help="cone angle in degrees (default: the scan's, 30 / 28 / 30)")
    parser.add_argument("--u-ref", type=vector, default=(-15.0, 0.0, 0.0),
                        help="free stream u,v,w in the CFD frame, m/s (default: the seed "
                             "UDF's -15,0,0)")
    add_probe_arguments(parser)


def add_tilt_arguments(parser) -> None:
    """--pitch, --roll, --tilt-compensation (`simulate`, `table`; other commands that define
    their own tilt options do not call this)."""
    parser.add_argument("--pitch", type=tilt_angle, default=0.0,
                        help="installation pitch in degrees (lidarjax.Mount; positive raises the "
                             "S0 side; -90 is a forward-looking nacelle lidar). Default level")
    parser.add_argument("--roll", type=tilt_angle, default=0.0,
                        help="installation roll in degrees (positive lowers the S1 side)")
    parser.add_argument("--tilt-compensation", action="store_true",
                        help="the instrument knows its tilt and reconstructs with the level "
                             "beam directions (default: it believes it is level)")


def add_probe_arguments(parser) -> None:
    parser.add_argument("--probe", choices=("point", "pulsed", "cw"), default="point",
                        help="probe volume: point (default), pulsed (Windcube: Gaussian pulse * "
                             "range gate) or cw (ZephIR: Lorentzian)")
    parser.add_argument("--probe-nodes", type=positive_int, default=None,
                        help="quadrature nodes along the beam (default 9 pulsed, 17 cw; `series` "
                             "adds nodes to resolve its turbulence box unless this is given)")
    parser.add_argument("--probe-scale", type=positive_float, default=None,
                        help="model scale s of the CFD (1:s); probe lengths are divided by s "
                             "(e.g. 100 for a 1:100 wind-tunnel-scale platform)")


def make_probe(args):
    scale = 1.0 if args.probe_scale is None else args.probe_scale
    if not (math.isfinite(scale) and scale > 0):
        raise ValueError(f"--probe-scale must be a finite positive number, got {scale}")
    if args.probe_nodes is not None and args.probe_nodes < 1:
        raise ValueError(f"--probe-nodes must be at least 1, got {args.probe_nodes}")
    if args.probe == "point":
        for opt, value in (("--probe-nodes", args.probe_nodes),
                           ("--probe-scale", args.probe_scale)):
            if value is not None:
                raise ValueError(f"{opt} applies to a probe volume, but --probe is point; "
                                 "add --probe pulsed or --probe cw, or drop it")
        return None
    kind = PulsedProbe if args.probe == "pulsed" else CWProbe
    probe = kind() if args.probe_nodes is None else kind(n_nodes=args.probe_nodes)
    return probe.scaled(scale) if scale != 1.0 else probe


def vector(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers 'u,v,w', got {text!r}") from None
    if len(values) != 3:
        raise argparse.ArgumentTypeError(f"expected three numbers 'u,v,w', got {text!r}")
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected three finite numbers 'u,v,w', got {text!r}")
    if math.hypot(values[0], values[1]) == 0.0:
        raise argparse.ArgumentTypeError(
            f"the free stream must have a horizontal component (its direction defines the "
            f"table), got {text!r}")
    return values


def make_scan(name: str, cone: float | None, *, tilt_compensation: bool = False):
    make = getattr(scans, name)
    if cone is None:
        return make(tilt_compensation=tilt_compensation)
    return make(cone, tilt_compensation=tilt_compensation)


def selected_betas(args, settings) -> list[float]:
    if getattr(args, "all", False):
        return [float(b) for b in settings.betas]
    return [float(settings.beta if args.beta is None else args.beta)]


def field_pattern(pattern: str, beta: str) -> str:
    """`pattern` with ``{beta}`` replaced; any other brace field is an error naming the fix.

    Literal braces are written ``{{`` and ``}}``.
    """
    try:
        fields = [f for _, f, _, _ in string.Formatter().parse(pattern) if f is not None]
    except ValueError as err:
        raise ValueError(f"--field {pattern!r}: {err}; write a literal brace as '{{{{' or "
                         "'}}}}'") from None
    bad = [f for f in fields if f != "beta"]
    if bad:
        raise ValueError(f"--field {pattern!r}: unknown placeholder {{{bad[0]}}}; the only "
                         "placeholder is {beta} (write a literal brace as '{{' or '}}')")
    try:
        return pattern.format(beta=beta)
    except (ValueError, IndexError, KeyError) as err:
        raise ValueError(f"--field {pattern!r}: {err}; write the placeholder as {{beta}}") from None


def field_paths(args, betas):
    if len(betas) > 1 and "{beta}" not in args.field:
        raise ValueError(f"--field {args.field!r} must contain '{{beta}}' to name one CFD run "
                         "per platform rotation (e.g. 'runs/platform_{beta}.npz')")
    paths = {b: Path(field_pattern(args.field, format_number(b))) for b in betas}
    missing = [str(p) for p in paths.values() if not (p.is_file() or p.is_dir())]
    if missing:
        raise FileNotFoundError(f"CFD field file(s) not found: {', '.join(missing)}")
    folders = [str(p) for p in paths.values() if p.is_dir() and not is_openfoam_case(p)]
    if folders:
        raise ValueError(f"--field {folders[0]}: a folder that is not an OpenFOAM case (no "
                         "constant/polyMesh, plain or in processor0/) nor one of its time "
                         "folders; give a case folder, CASE/<time>, or a field file")
    return paths
