"""`lidarjax scan`: a scanning lidar (preset or the layout of a real scan file) in a field,
written as CF NetCDF (time x beam x range), with a plot of the PPI on its cone or the RHI on
its plane.

The scan is a `lidarjax.scanning` preset (``ppi``, ``rhi``, ``stare``, ``vad``, ``rosette``)
or the layout of a Halo ``.hpl`` or Windcube scanning ``.nc`` file (its rays, gates and
times). The field is a uniform wind (``--wind SPEED,DIRECTION``) or a CFD field file
(``--field``). ``--scans N`` flies N repetitions through time (`lidarjax.simulate_scan_series`).
"""

from __future__ import annotations

import argparse
import math
from pathlib import Path

import numpy as np

from ..io import read_hpl, read_windcube_scan, write_scan_netcdf
from ..io.fields import check_field_file, load_field
from ..mount import Mount
from ..probe import PointProbe
from ..scanning import (
    INSTRUMENTS,
    gate_ranges,
    instrument_probe,
    ppi,
    rhi,
    simulate_scan,
    simulate_scan_series,
    spinner_rosette,
    stare,
    vad,
)
from ..scenes import uniform
from ._common import check_output_file, finite_float, positive_float, positive_int

PRESETS = ("ppi", "rhi", "stare", "vad", "rosette")


def _triple(text: str) -> tuple[float, float, float]:
    try:
        values = tuple(float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected three numbers 'x,y,z', got {text!r}") from None
    if len(values) != 3 or not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"expected three finite numbers 'x,y,z', got {text!r}")
    return values


def _wind(text: str) -> tuple[float, float]:
    try:
        speed, direction = (float(v) for v in text.replace(" ", "").split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected 'SPEED,DIRECTION' (m/s, degrees), got {text!r}") from None
    if not (math.isfinite(speed) and math.isfinite(direction)):
        raise argparse.ArgumentTypeError(f"expected finite numbers, got {text!r}")
    return speed, direction


def register(sub) -> None:
    p = sub.add_parser(
        "scan", help="a scanning lidar (PPI, RHI, stare, VAD, rosette or a scan file) in a field",
        description="Simulate a scanning lidar: a preset or the layout of a Halo .hpl / Windcube "
                    ".nc scan file, in a uniform wind or a CFD field; write CF NetCDF (time x "
                    "beam x range) and plot the PPI on its cone or the RHI on its plane.",
        epilog="example: lidarjax scan ppi --elevation 3 --n-rays 72 --gates 100 --wind 8,270 "
               "--out ppi.nc --plot ppi.png",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("scan", help=f"a preset ({', '.join(PRESETS)}) or a .hpl / .nc scan file")
    p.add_argument("--elevation", type=finite_float, default=3.0, help="degrees (ppi, vad, stare)")
    p.add_argument("--azimuth", type=finite_float, default=0.0, help="degrees (rhi, stare)")
    p.add_argument("--start", type=finite_float, default=None,
                   help="first angle of a sector (ppi: azimuth, rhi: elevation), degrees")
    p.add_argument("--stop", type=finite_float, default=None,
                   help="last angle of a sector, degrees (ppi default: a full turn)")
    p.add_argument("--n-rays", type=positive_int, default=None, help="rays per sweep")
    p.add_argument("--accumulation", type=positive_float, default=1.0, help="seconds per ray")
    p.add_argument("--mode", choices=("continuous", "step"), default=None,
                   help="continuous sweep or step-and-stare")
    p.add_argument("--n-sub", type=positive_int, default=1,
                   help="sub-rays averaged over each ray's swept arc")
    p.add_argument("--gates", type=positive_int, default=100, help="range gates")
    p.add_argument("--gate-length", type=positive_float, default=None,
                   help="m (default: the instrument's)")
    p.add_argument("--instrument", choices=tuple(INSTRUMENTS), default="halo_streamline",
                   help="pulsed probe per gate (gate length, pulse)")
    p.add_argument("--point-probe", action="store_true", help="sample gate centres only")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--wind", type=_wind, default=(10.0, 270.0),
                     help="uniform wind 'SPEED,DIRECTION' (m/s, meteorological degrees)")
    src.add_argument("--field", help="a CFD field file (.npz, .nc, ...) instead of --wind")
    p.add_argument("--location", type=_triple, default=(0.0, 0.0, 0.0), help="lidar 'x,y,z' (m)")
    p.add_argument("--beta", type=finite_float, default=0.0, help="mount rotation, degrees")
    p.add_argument("--pitch", type=finite_float, default=0.0, help="degrees (nacelle: -90)")
    p.add_argument("--roll", type=finite_float, default=0.0, help="degrees")
    p.add_argument("--scans", type=positive_int, default=1, help="repetitions flown through time")
    p.add_argument("--out", default="scan.nc", help="CF NetCDF output (default scan.nc)")
    p.add_argument("--plot", default=None, help="PNG of the scan on its cone or plane")
    p.set_defaults(func=run)


def make_pattern(args):
    """The `ScanPattern` the arguments describe (a preset or a scan file's layout)."""
    name = args.scan.lower()
    if name not in PRESETS:
        path = Path(args.scan)
        if path.suffix.lower() == ".hpl":
            return read_hpl(path).pattern()
        if path.suffix.lower() == ".nc":
            return read_windcube_scan(path).pattern()
        if not path.exists():
            raise ValueError(f"scan {args.scan!r} is neither a preset ({', '.join(PRESETS)}) nor a "
                             f".hpl / .nc scan file")
        raise ValueError(f"scan file {path} is not .hpl (Halo) or .nc (Windcube); give one of those")
    gate = args.gate_length or INSTRUMENTS[args.instrument]["gate_length"]
    ranges = gate_ranges(args.gates, gate)
    kw = {"accumulation": args.accumulation}
    if name == "ppi":
        return ppi(args.elevation, ranges, azimuth_start=args.start or 0.0, azimuth_stop=args.stop,
                   n_rays=args.n_rays or 360, mode=args.mode or "continuous", n_sub=args.n_sub, **kw)
    if name == "rhi":
        return rhi(args.azimuth, ranges, elevation_start=args.start or 0.0,
                   elevation_stop=90.0 if args.stop is None else args.stop, n_rays=args.n_rays or 90,
                   mode=args.mode or "continuous", n_sub=args.n_sub, **kw)
    if name == "vad":
        return vad(args.elevation, ranges, n_rays=args.n_rays or 24, mode=args.mode or "step",
                   n_sub=args.n_sub, **kw)
    if name == "stare":
        return stare(args.azimuth, args.elevation, ranges, n_rays=args.n_rays or 1, **kw)
    return spinner_rosette(ranges, n_points=args.n_rays or 400, n_sub=args.n_sub)


def run(args) -> int:
    out = check_output_file(args.out)
    plot = check_output_file(args.plot, option="--plot") if args.plot else None
    pattern = make_pattern(args)
    if args.field:
        check_field_file(args.field)
        field = load_field(args.field)
    else:
        field = uniform(*args.wind)
    probe = PointProbe() if args.point_probe else instrument_probe(
        args.instrument, gate_length=args.gate_length)
    mount = Mount(args.location, beta=args.beta, pitch=args.pitch, roll=args.roll)
    if args.scans > 1:
        res = simulate_scan_series(field, pattern, mount, n_scans=args.scans, probe=probe)
    else:
        res = simulate_scan(field, pattern, mount, probe=probe)
    write_scan_netcdf(out, res.los, azimuth=res.azimuth, elevation=res.elevation, ranges=res.ranges,
                      ray_time=res.times, flags=res.flags, title=f"lidarjax scan {args.scan}")
    los = np.asarray(res.los)
    print(f"{pattern.n_rays} rays x {pattern.n_gates} gates x {args.scans} scan(s) ({pattern.kind}); "
          f"LOS {np.nanmin(los):.2f} to {np.nanmax(los):.2f} m/s, {np.isnan(los).mean():.1%} NaN; "
          f"wrote {out}")
    if plot is not None:
        plot_scan(res, pattern.kind, plot)
        print(f"wrote {plot}")
    return 0


def plot_scan(res, kind: str, path) -> None:
    """The last scan's LOS on its geometry: a PPI (or any scan) seen from above on its cone
    (horizontal distance east and north of the lidar), an RHI on its vertical plane
    (horizontal distance along the azimuth, height)."""
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
        az = np.deg2rad(np.asarray(res.azimuth))[:, None]
        x = rel[..., 0] * np.sin(az) + rel[..., 1] * np.cos(az)
        y = rel[..., 2]
        ax.set_xlabel("horizontal distance along the azimuth (m)")
        ax.set_ylabel("height above the lidar (m)")
        ax.set_title("RHI on its vertical plane")
    else:
        x, y = rel[..., 0], rel[..., 1]
        ax.set_xlabel("east of the lidar (m)")
        ax.set_ylabel("north of the lidar (m)")
        ax.set_title(f"{kind.upper()} on its cone, seen from above")
    lim = np.nanmax(np.abs(los)) if np.isfinite(los).any() else 1.0
    sc = ax.scatter(x.ravel(), y.ravel(), c=los.ravel(), s=4, cmap="RdBu_r", vmin=-lim, vmax=lim)
    ax.set_aspect("equal")
    fig.colorbar(sc, ax=ax, label="LOS velocity (m/s, + away)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
