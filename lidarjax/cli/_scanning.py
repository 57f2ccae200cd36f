"""Scanning lidars on the command line, shared by `lidarjax scan`, `lidarjax simulate` and
`lidarjax series`: the scan-pattern options, the `ScanPattern` they describe (a
`lidarjax.scanning` preset or the layout of a Halo ``.hpl`` / Windcube scanning ``.nc``
file), the scanning instrument's probe, the CFD region a scan samples, the checks that
keep profiler-only and scanning-only options apart, and the plot of a scan on its cone or
plane.

Defaults of the pattern options (they are None in the parsed arguments, so that a command
can tell whether one was given): elevation 3 degrees, azimuth 0, a PPI over a full turn
from azimuth 0 (360 rays), an RHI from elevation 0 to 90 (90 rays), a VAD of 24 rays
(step-and-stare), one stare ray, a rosette of 400 points; 1 s accumulation, 1 sub-ray,
100 gates of the instrument's gate length (Halo StreamLine: 30 m).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._util import atomic_path
from ..beam import pattern_geometry
from ..io import read_hpl, read_windcube_scan
from ..probe import CWProbe, PointProbe
from ..scanning import (
    INSTRUMENTS,
    gate_ranges,
    instrument_probe,
    ppi,
    rhi,
    spinner_rosette,
    stare,
    vad,
)
from ._common import SCAN_CHOICES, finite_float, positive_float, positive_int

#: The scanning presets (`lidarjax.scanning`).
PRESETS = ("ppi", "rhi", "stare", "vad", "rosette")
#: Suffixes of the scan files whose layout a scan can take.
SCAN_FILE_SUFFIXES = (".hpl", ".nc")

#: Pattern options: parsed name -> option (set a preset's geometry and timing).
GEOMETRY_OPTIONS = {
    "elevation": "--elevation", "azimuth": "--azimuth", "sector_start": "--sector-start",
    "sector_stop": "--sector-stop", "n_rays": "--n-rays", "accumulation": "--accumulation",
    "mode": "--mode", "n_sub": "--n-sub", "gates": "--gates",
}
#: Probe options of a scanning instrument (presets and scan files).
INSTRUMENT_OPTIONS = {"gate_length": "--gate-length", "instrument": "--instrument"}

_DEFAULT_INSTRUMENT = "halo_streamline"


def is_scanning(name: str) -> bool:
    """True for a scanning preset (`PRESETS`) or a ``.hpl`` / ``.nc`` scan file name."""
    return str(name).lower() in PRESETS or Path(str(name)).suffix.lower() in SCAN_FILE_SUFFIXES


def is_scan_file(name: str) -> bool:
    """True for a scan file name (not a preset)."""
    return str(name).lower() not in PRESETS and is_scanning(name)


def scan_choice(text: str) -> str:
    """argparse type of ``--scan`` in `simulate` and `series`: a profiler (`SCAN_CHOICES`), a
    scanning preset or a ``.hpl`` / ``.nc`` scan file (its existence is checked when read)."""
    if text in SCAN_CHOICES or is_scanning(text):
        return text.lower() if text.lower() in PRESETS else text
    suffix = Path(text).suffix
    what = f"a file with suffix {suffix!r}" if suffix else repr(text)
    raise argparse.ArgumentTypeError(
        f"{what} is no scan; give a profiler ({', '.join(SCAN_CHOICES)}), a scanning preset "
        f"({', '.join(PRESETS)}) or a Halo .hpl / Windcube .nc scan file")


def add_scan_pattern_arguments(parser, *, sector=("--sector-start", "--sector-stop"),
                               title: str | None = None) -> None:
    """The options of a scanning preset's geometry and timing and of the instrument's probe
    (module docs for their defaults). `sector`: the option names of a sector's first and last
    angle (``lidarjax scan`` also accepts ``--start`` / ``--stop``)."""
    g = parser.add_argument_group(title) if title else parser
    g.add_argument("--elevation", type=finite_float, default=None,
                   help="degrees (ppi, vad, stare; default 3)")
    g.add_argument("--azimuth", type=finite_float, default=None,
                   help="degrees clockwise from the mount's north (rhi, stare; default 0)")
    g.add_argument(*sector[:1], *([] if sector[0] == "--sector-start" else ["--sector-start"]),
                   dest="sector_start", type=finite_float, default=None,
                   help="first angle of a sector (ppi: azimuth, rhi: elevation), degrees")
    g.add_argument(*sector[1:], *([] if sector[1] == "--sector-stop" else ["--sector-stop"]),
                   dest="sector_stop", type=finite_float, default=None,
                   help="last angle of a sector, degrees (ppi default: a full turn; rhi: 90)")
    g.add_argument("--n-rays", type=positive_int, default=None,
                   help="rays per sweep (default ppi 360, rhi 90, vad 24, stare 1, rosette 400)")
    g.add_argument("--accumulation", type=positive_float, default=None,
                   help="seconds per ray (default 1)")
    g.add_argument("--mode", choices=("continuous", "step"), default=None,
                   help="continuous sweep or step-and-stare (default: continuous, vad step)")
    g.add_argument("--n-sub", type=positive_int, default=None,
                   help="sub-rays averaged over each ray's swept arc (default 1)")
    g.add_argument("--gates", type=positive_int, default=None, help="range gates (default 100)")
    g.add_argument("--gate-length", type=positive_float, default=None,
                   help="m (default: a scan file's, else the instrument's)")
    g.add_argument("--instrument", choices=tuple(INSTRUMENTS), default=None,
                   help="pulsed probe per gate: gate length and pulse (default halo_streamline)")


def read_scan_source(args):
    """``(pattern, gate_length)``: the `ScanPattern` of ``args.scan`` (a preset with the
    pattern options, or a scan file's layout) and the gate length in m the probe uses
    (``--gate-length``, else the file's, else the instrument's)."""
    name = str(args.scan).lower()
    instrument = args.instrument or _DEFAULT_INSTRUMENT
    if name not in PRESETS:
        path = Path(args.scan)
        suffix = path.suffix.lower()
        if suffix not in SCAN_FILE_SUFFIXES:
            if not path.exists():
                raise ValueError(f"scan {args.scan!r} is neither a preset ({', '.join(PRESETS)}) "
                                 "nor a .hpl / .nc scan file")
            raise ValueError(f"scan file {path} is not .hpl (Halo) or .nc (Windcube); give one "
                             "of those")
        given = [opt for dest, opt in GEOMETRY_OPTIONS.items() if getattr(args, dest) is not None]
        if given:
            raise ValueError(f"{given[0]} sets a preset's rays or gates, but the scan file {path} "
                             "has its own; drop it (or give a preset instead of the file)")
        scan = read_hpl(path) if suffix == ".hpl" else read_windcube_scan(path)
        gate = args.gate_length if args.gate_length is not None else float(scan.gate_length)
        return scan.pattern(), gate
    gate = args.gate_length or INSTRUMENTS[instrument]["gate_length"]
    ranges = gate_ranges(100 if args.gates is None else args.gates, gate)
    n_sub = 1 if args.n_sub is None else args.n_sub
    kw = {"accumulation": 1.0 if args.accumulation is None else args.accumulation}
    elevation = 3.0 if args.elevation is None else args.elevation
    azimuth = 0.0 if args.azimuth is None else args.azimuth
    start, stop = args.sector_start, args.sector_stop
    if name == "ppi":
        pattern = ppi(elevation, ranges, azimuth_start=start or 0.0, azimuth_stop=stop,
                      n_rays=args.n_rays or 360, mode=args.mode or "continuous", n_sub=n_sub, **kw)
    elif name == "rhi":
        pattern = rhi(azimuth, ranges, elevation_start=start or 0.0,
                      elevation_stop=90.0 if stop is None else stop, n_rays=args.n_rays or 90,
                      mode=args.mode or "continuous", n_sub=n_sub, **kw)
    elif name == "vad":
        pattern = vad(elevation, ranges, n_rays=args.n_rays or 24, mode=args.mode or "step",
                      n_sub=n_sub, **kw)
    elif name == "stare":
        pattern = stare(azimuth, elevation, ranges, n_rays=args.n_rays or 1, **kw)
    else:
        pattern = spinner_rosette(ranges, n_points=args.n_rays or 400, n_sub=n_sub)
    return pattern, float(gate)


def make_pattern(args):
    """The `ScanPattern` the arguments describe (a preset or a scan file's layout)."""
    return read_scan_source(args)[0]


def scanning_probe(args, gate_length: float):
    """The probe of a scanning scan in `simulate` and `series` (``--probe``): point (the gate
    centres), pulsed (`lidarjax.scanning.instrument_probe` of ``--instrument`` with the gate
    length, ``--probe-nodes`` nodes or nodes chosen for the field) or cw (`lidarjax.CWProbe`
    focused at every gate)."""
    if args.probe_scale is not None:
        raise ValueError("--probe-scale scales a profiler's probe; a scanning scan takes its "
                         "lengths in model metres: give --gate-length (and gate ranges) instead")
    if args.probe == "point":
        if args.probe_nodes is not None:
            raise ValueError("--probe-nodes applies to a probe volume, but --probe is point; add "
                             "--probe pulsed or --probe cw, or drop it")
        return PointProbe()
    if args.probe == "cw":
        return CWProbe() if args.probe_nodes is None else CWProbe(n_nodes=args.probe_nodes)
    return instrument_probe(args.instrument or _DEFAULT_INSTRUMENT, gate_length=gate_length,
                            n_nodes=args.probe_nodes)


def check_scan_options(args, *, profiler_only=()) -> bool:
    """Refuse options that do not apply to ``args.scan``; returns whether it is scanning.

    `profiler_only`: ``(option, given)`` pairs of the command's profiler options (an error
    with a scanning scan). The pattern and instrument options, and ``--plot`` where the
    command has it as a flag, are an error with a profiler scan."""
    scanning = is_scanning(args.scan)
    if scanning:
        for option, given in profiler_only:
            if given:
                raise ValueError(f"{option} applies to the profilers ({', '.join(SCAN_CHOICES)}), "
                                 f"not to the scanning scan {args.scan!r}; drop it")
        return True
    scanning_only = {**GEOMETRY_OPTIONS, **INSTRUMENT_OPTIONS}
    for dest, option in scanning_only.items():
        if getattr(args, dest, None) is not None:
            raise ValueError(f"{option} applies to scanning scans (a preset: {', '.join(PRESETS)}; "
                             f"or a .hpl / .nc file), not to the profiler {args.scan}; drop it or "
                             "give e.g. --scan ppi")
    if getattr(args, "plot", None) is True:
        raise ValueError(f"--plot draws a scanning scan on its cone or plane, not the profiler "
                         f"{args.scan}; drop it or give e.g. --scan ppi")
    return False


def scan_region(pattern, mounts, probe=None) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` absolute CFD metres, float64 ``(3,)`` each: the box every sub-ray of
    `pattern` samples from each of `mounts` (one `lidarjax.Mount`, a batch, or a list), the
    probe's whole support around every gate (cut at the lidar) included; the region to load
    from a CFD run (`lidarjax.io.load_field(region=...)`, which adds the interpolation
    margin). The analogue of `lidarjax.scan_bounds` for a `ScanPattern` (platform motion not
    included). Needs concrete numbers."""
    r = np.asarray(pattern.ranges, np.float64)
    if probe is None or isinstance(probe, PointProbe):
        near = far = r
    else:  # the support covers the nodes at any node count (chosen later for the field)
        reach = np.minimum(np.asarray(probe.support(jnp.asarray(r)), np.float64), r)
        near, far = r - reach, r + reach
    if isinstance(mounts, list | tuple):
        mounts = list(mounts)
    elif mounts.batch_shape:
        mounts = [mounts[k] for k in range(mounts.batch_shape[0])]
    else:
        mounts = [mounts]
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    for mount in mounts:
        loc, n = pattern_geometry(pattern, mount)  # (3,), (B, 3)
        pts = np.concatenate([(loc + d[:, None, None] * n[None]).reshape(-1, 3)
                              for d in (near, far)])
        lo, hi = np.minimum(lo, pts.min(axis=0)), np.maximum(hi, pts.max(axis=0))
    return lo, hi


def describe(res, kind: str) -> str:
    """One line: rays x gates (x scans), gate ranges, LOS span and NaN share of a result."""
    los = np.asarray(res.los)
    rng = np.asarray(res.ranges)
    n = f" x {los.shape[0]} scans" if los.ndim == 3 else ""
    span = (f"LOS {np.nanmin(los):.2f} to {np.nanmax(los):.2f} m/s" if np.isfinite(los).any()
            else "LOS all NaN")
    return (f"{los.shape[-2]} rays x {los.shape[-1]} gates{n} ({kind}), ranges {rng[0]:g} to "
            f"{rng[-1]:g} m; {span}, {np.isnan(los).mean():.1%} NaN")


def explain_scan_nans(res, field) -> str | None:
    """One line on the NaN LOS of `res` in `field` (None when there are none): how many gate
    centres lie outside the field's grid (its extent named), how many inside it where it has
    no value (terrain, a solid, outside the mesh), and what to change."""
    los = np.asarray(res.los)
    if not np.isnan(los).any():
        return None
    share = f"{np.isnan(los).mean():.1%} of the LOS are NaN"
    pts = np.asarray(res.points, np.float64)
    grid = getattr(field, "grid", field)
    out = np.zeros(pts.shape[:-1], bool)
    extent = ""
    if all(hasattr(grid, a) for a in ("x", "y", "z")):
        axes = [np.asarray(getattr(grid, a), np.float64) for a in ("x", "y", "z")]
        for k, a in enumerate(axes):
            out |= (pts[..., k] < a.min()) | (pts[..., k] > a.max())
        extent = " (" + ", ".join(f"{n} {a.min():g}..{a.max():g}"
                                  for n, a in zip("xyz", axes, strict=True)) + " m as read)"
    dry = ~np.isfinite(np.asarray(field.sample(jnp.asarray(pts)))).all(axis=-1) & ~out
    parts = []
    if out.any():
        parts.append(f"{int(out.sum())} of {out.size} gate centres lie outside the CFD "
                     f"field{extent}")
    if dry.any():
        parts.append(f"{int(dry.sum())} gate centres lie inside the field where it has no value "
                     "(terrain, a solid or outside the mesh)")
    if not parts:
        return (f"{share}: every gate centre has a value; probe nodes around them lie outside "
                "the field or in a solid (--probe point samples the centres only)")
    return (f"{share}: " + "; ".join(parts) + "; fewer --gates, a shorter --gate-length, "
            "another --elevation or lidar location keeps the scan in the flow")


def rhi_plane(directions, elevation, rel) -> np.ndarray:
    """Signed horizontal distance of points `rel` ``(r, g, 3)`` (CFD metres from the lidar)
    along the horizontal axis of an RHI's vertical plane: the dominant horizontal direction
    of the rays `directions` ``(r, 3)`` (CFD frame, any mount), pointing along the ray of
    lowest `elevation` (degrees)."""
    h = np.asarray(directions, np.float64)[:, :2]
    if not np.any(np.hypot(h[:, 0], h[:, 1]) > 1e-9):  # every ray vertical: any axis
        return np.asarray(rel)[..., 0]
    axis = np.linalg.svd(h, full_matrices=False)[2][0]
    low = int(np.argmin(np.asarray(elevation)))
    if h[low] @ axis < 0:
        axis = -axis
    return np.asarray(rel)[..., 0] * axis[0] + np.asarray(rel)[..., 1] * axis[1]


def plot_scan(res, kind: str, path) -> None:
    """The last scan's LOS on its geometry: a PPI (or any scan) seen from above on its cone
    (horizontal distance east and north of the lidar), an RHI on its vertical plane
    (horizontal distance along the azimuth, height). Written atomically."""
    import matplotlib  # noqa: PLC0415 - optional extra, imported when drawing

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415

    los = np.asarray(res.los)
    los = los.reshape(-1, *los.shape[-2:])[-1]
    pts = np.asarray(res.points)
    origin = pts[:, 0] - np.asarray(res.ranges)[0] * np.asarray(res.directions)
    rel = pts - origin[:, None, :]
    fig, ax = plt.subplots(figsize=(6, 5))
    if kind == "rhi":
        x, y = rhi_plane(res.directions, res.elevation, rel), rel[..., 2]
        ax.set_xlabel("horizontal distance in the scan's plane (m)")
        ax.set_ylabel("height above the lidar (m)")
        ax.set_title("RHI on its vertical plane")
    else:
        x, y = rel[..., 0], rel[..., 1]
        ax.set_xlabel("x from the lidar, CFD frame (m)")
        ax.set_ylabel("y from the lidar, CFD frame (m)")
        ax.set_title(f"{kind.upper()} on its cone, seen from above")
    lim = np.nanmax(np.abs(los)) if np.isfinite(los).any() else 1.0
    lim = lim if math.isfinite(lim) and lim > 0 else 1.0
    sc = ax.scatter(x.ravel(), y.ravel(), c=los.ravel(), s=4, cmap="RdBu_r", vmin=-lim, vmax=lim)
    ax.set_aspect("equal")
    fig.colorbar(sc, ax=ax, label="LOS velocity (m/s, + away)")
    fig.tight_layout()
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
