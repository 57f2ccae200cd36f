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
import warnings
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._util import atomic_path, import_optional
from ..beam import pattern_geometry
from ..io import read_hpl, read_windcube_scan
from ..io.hpl import INTENSITY_THRESHOLD, HaloScan
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
from ._common import (
    SCAN_CHOICES,
    finite_float,
    input_file,
    positive_float,
    positive_int,
    warning_line,
)

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


def scan_source(text: str) -> str:
    """argparse type of `lidarjax scan`'s scan: a preset or a ``.hpl`` / ``.nc`` scan file,
    which must exist (any other name is refused when the scan is read)."""
    if is_scan_file(text):
        return input_file(text)
    return text


def scan_choice(text: str) -> str:
    """argparse type of ``--scan`` in `simulate` and `series`: a profiler (`SCAN_CHOICES`), a
    scanning preset or an existing ``.hpl`` / ``.nc`` scan file."""
    if text in SCAN_CHOICES or is_scanning(text):
        return text.lower() if text.lower() in PRESETS else scan_source(text)
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


def read_scan_source(args, *, with_file: bool = False):
    """``(pattern, gate_length)``: the `ScanPattern` of ``args.scan`` (a preset with the
    pattern options, or a scan file's layout) and the gate length in m the probe uses
    (``--gate-length``, else the file's, else the instrument's). `with_file`: also the scan
    file read (`lidarjax.io.HaloScan` or `lidarjax.io.WindcubeScan`; None for a preset), as
    a third item."""
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
        with warnings.catch_warnings(record=True) as caught:  # one line each on stderr
            warnings.simplefilter("always")
            scan = read_hpl(path) if suffix == ".hpl" else read_windcube_scan(path)
        for w in caught:
            warning_line(args.command, w.message)
        gate = args.gate_length if args.gate_length is not None else float(scan.gate_length)
        return (scan.pattern(), gate, scan) if with_file else (scan.pattern(), gate)
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
    return (pattern, float(gate), None) if with_file else (pattern, float(gate))


def measured_los(scan):
    """``(los, title)``: a scan file's own Doppler ``(r, g)`` m/s, NaN where the instrument's
    data are rejected (a Halo file: intensity below `lidarjax.io.INTENSITY_THRESHOLD`; a
    Windcube file: its status), and a title naming the file and the rejection."""
    name = Path(scan.path).name
    if isinstance(scan, HaloScan):
        return scan.radial_velocity(), f"measured, {name}\n(intensity < {INTENSITY_THRESHOLD:g})"
    return scan.radial_velocity(), f"measured, {name}\n(instrument status rejected)"


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


def _edges(centres: np.ndarray, fallback: float) -> np.ndarray:
    """Cell edges ``(n + 1,)`` around sorted `centres` ``(n,)``: midpoints, the outer two half
    a step out (`fallback` the width of a single cell)."""
    c = np.asarray(centres, np.float64)
    if c.size == 1:
        return np.array([c[0] - fallback / 2, c[0] + fallback / 2])
    mid = (c[1:] + c[:-1]) / 2
    return np.concatenate([[c[0] - (mid[0] - c[0])], mid, [c[-1] + (c[-1] - mid[-1])]])


def _ray_half_widths(angle: np.ndarray, *, circular: bool) -> np.ndarray:
    """Half the angular width (degrees) of each ray's cell: half the gap to its nearest
    neighbour in angle (around the circle for azimuths), 0.5 where every ray shares one
    angle."""
    a = np.asarray(angle, np.float64) % 360 if circular else np.asarray(angle, np.float64)
    distinct = np.unique(np.round(a, 6))
    if distinct.size < 2:
        return np.full(a.shape, 0.5)
    if circular:
        ext = np.concatenate([distinct - 360, distinct, distinct + 360])
    else:
        ext = np.concatenate([[2 * distinct[0] - distinct[1]], distinct,
                              [2 * distinct[-1] - distinct[-2]]])
    idx = np.searchsorted(ext, np.round(a, 6))
    gap = np.minimum(ext[idx] - ext[idx - 1], ext[idx + 1] - ext[idx])
    return gap / 2


def _polar_cells(angle, half, range_edges, *, rhi: bool, steps: int = 4):
    """Polygons ``(r * g, 2 * steps + 2, 2)`` of the cells between each ray's edges
    (``angle -+ half``, degrees) and its gates' ends `range_edges` ``(g + 1,)`` m: seen from
    above for azimuths (``x = r sin a``, ``y = r cos a``; ranges on the ground), in the
    vertical plane for elevations (``x = r cos e``, ``z = r sin e``)."""
    t = np.linspace(-1.0, 1.0, steps + 1)
    ang = np.radians(np.asarray(angle)[:, None] + np.asarray(half)[:, None] * t[None])  # (r, s)
    near, far = range_edges[:-1], range_edges[1:]  # (g,)
    th = np.concatenate([ang, ang[:, ::-1]], axis=1)  # (r, 2s): along the near edge, back the far
    rad = np.concatenate([near[:, None].repeat(t.size, 1), far[:, None].repeat(t.size, 1)], axis=1)
    if rhi:
        x = rad[None] * np.cos(th)[:, None]
        y = rad[None] * np.sin(th)[:, None]
    else:
        x = rad[None] * np.sin(th)[:, None]
        y = rad[None] * np.cos(th)[:, None]
    return np.stack([x, y], axis=-1).reshape(-1, 2 * t.size, 2)


def _rings(ax, r_max: float, *, upper: bool) -> None:
    """Range rings at round ranges up to `r_max` m, labelled in m (a half circle above the
    horizon for an RHI)."""
    from matplotlib.ticker import MaxNLocator  # noqa: PLC0415

    ticks = [v for v in MaxNLocator(nbins=4, steps=[1, 2, 2.5, 5, 10]).tick_values(0, r_max)
             if 0 < v <= r_max * 1.001]
    phi = np.linspace(0, np.pi if upper else 2 * np.pi, 181)
    for v in ticks:
        ax.plot(v * np.cos(phi), v * np.sin(phi), color="0.35", lw=0.6, zorder=3)
        label_at = np.radians(80.0 if upper else 45.0)
        ax.annotate(f"{v:g} m", (v * np.cos(label_at), v * np.sin(label_at)), fontsize=7,
                    color="0.2", ha="left", va="bottom", zorder=4,
                    bbox=dict(boxstyle="round,pad=0.1", fc="white", ec="none", alpha=0.7))


def _scan_panel(ax, geometry, values, kind, norm, cmap, title):
    """One panel: the gates of `values` ``(r, g)`` as cells of the scan's geometry."""
    from matplotlib.collections import PolyCollection  # noqa: PLC0415

    az, el, ranges, times = geometry
    r_edges = np.maximum(_edges(ranges, ranges[0] if ranges.size else 1.0), 0.0)
    if kind == "stare":  # one direction: time against range
        t_edges = _edges(times, 1.0)
        mesh = ax.pcolormesh(t_edges, r_edges, values.T, cmap=cmap, norm=norm, shading="flat")
        ax.set_xlabel("time from the first ray's start (s)")
        ax.set_ylabel("range along the beam (m)")
        ax.set_title(title, fontsize=9)
        return mesh
    rhi = kind == "rhi"
    angle = el if rhi else az
    half = _ray_half_widths(angle, circular=not rhi)
    if not rhi:  # seen from above: the ground range of each gate's ends
        cos_el = np.cos(np.radians(np.mean(el)))
        r_plot = r_edges * cos_el
    else:
        r_plot = r_edges
    steps = int(np.clip(np.ceil(np.max(half)), 2, 45))  # arcs drawn in steps of 2 degrees or less
    cells = _polar_cells(angle, half, r_plot, rhi=rhi, steps=steps)
    coll = PolyCollection(cells, array=np.ma.masked_invalid(values.ravel()), cmap=cmap, norm=norm,
                          linewidths=0, antialiaseds=False)
    ax.add_collection(coll)
    r_max = float(r_plot[-1])
    _rings(ax, r_max, upper=rhi)
    lo, hi = cells.reshape(-1, 2).min(axis=0), cells.reshape(-1, 2).max(axis=0)
    pad = 0.04 * r_max
    ax.set_xlim(min(lo[0], 0.0) - pad, max(hi[0], 0.0) + pad)
    ax.set_ylim(min(lo[1], 0.0) - pad, max(hi[1], 0.0) + pad)
    if rhi:
        ax.set_xlabel("horizontal distance along the azimuth (m)")
        ax.set_ylabel("height above the lidar (m)")
    else:
        ax.set_xlabel("east of the lidar, CFD x (m)")
        ax.set_ylabel("north of the lidar, CFD y (m)")
    ax.set_aspect("equal")
    ax.set_title(title, fontsize=9)
    return coll


def scan_geometry(res):
    """``(azimuth, elevation, ranges, times)`` of a result's rays for drawing: azimuth
    (degrees clockwise from CFD ``+y``) and elevation (above the CFD horizon) of each ray's
    direction in the CFD frame (so a rotated mount draws where its rays go), gate-centre
    ranges (m) and ray times (s, the last scan)."""
    d = np.asarray(res.directions, np.float64)
    az = np.degrees(np.arctan2(d[:, 0], d[:, 1]))
    el = np.degrees(np.arcsin(np.clip(d[:, 2], -1.0, 1.0)))
    times = np.asarray(res.times, np.float64).reshape(-1, d.shape[0])[-1]
    return az, el, np.asarray(res.ranges, np.float64), times


def plot_scan(res, kind: str, path, *, measured=None, measured_title: str = "measured") -> None:
    """The last scan's LOS as radar displays draw it: each gate a filled cell between its
    ray's edges (half-way to the neighbouring rays) and its gate's ends (half-way to the
    neighbouring gates), coloured on a diverging map centred on zero. A PPI or VAD seen from
    above with labelled range rings (ground range, CFD x east and y north), an RHI on its
    vertical plane with labelled range arcs, a stare as time against range; other scans as
    a PPI. `measured` ``(r, g)`` (m/s, NaN where the instrument's data were rejected) is
    drawn beside the simulation on the same colour scale, its rejected gates grey
    (`measured_title` names the source and threshold). Written atomically; needs the
    ``plot`` extra (matplotlib)."""
    matplotlib = import_optional("matplotlib", "plot", "Drawing the scan")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt  # noqa: PLC0415
    from matplotlib.colors import Normalize  # noqa: PLC0415

    los = np.asarray(res.los, np.float64)
    los = los.reshape(-1, *los.shape[-2:])[-1]
    geometry = scan_geometry(res)
    shown = [los] + ([np.asarray(measured, np.float64)] if measured is not None else [])
    # symmetric about zero: the simulation's largest |LOS| and the measured 99th percentile
    # (a few noisy gates do not wash out the rest)
    sim = np.abs(los[np.isfinite(los)])
    meas = np.abs(shown[-1][np.isfinite(shown[-1])]) if measured is not None else np.zeros(0)
    lim = max(float(sim.max()) if sim.size else 0.0,
              float(np.percentile(meas, 99)) if meas.size else 0.0)
    lim = lim if math.isfinite(lim) and lim > 0 else 1.0
    norm = Normalize(-lim, lim)
    cmap = matplotlib.colormaps["RdBu_r"].with_extremes(bad="0.75")
    draw = kind if kind in ("ppi", "rhi", "stare", "vad") else "ppi"
    name = {"ppi": "PPI", "vad": "VAD", "rhi": "RHI", "stare": "stare"}[draw]
    n = len(shown)
    fig, axes = plt.subplots(1, n, figsize=(5.2 * n + 1.2, 5.0), squeeze=False, layout="constrained")
    axes = axes[0]
    panels = [(los, f"simulated {name}")]
    if measured is not None:
        panels.insert(0, (shown[1], f"{measured_title}; grey: rejected"))
    for ax, (values, title) in zip(axes, panels, strict=True):
        artist = _scan_panel(ax, geometry, values, draw, norm, cmap, title)
    fig.colorbar(artist, ax=list(axes), label="LOS velocity (m/s, + away from the lidar)",
                 extend="both", shrink=0.85)
    try:
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=110, format="png")
    finally:
        plt.close(fig)
