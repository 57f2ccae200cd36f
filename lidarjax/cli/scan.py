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

from ..io import write_scan_netcdf
from ..io.fields import check_field_file, load_field
from ..mount import Mount
from ..probe import PointProbe
from ..scanning import instrument_probe, scan_points, simulate_scan, simulate_scan_series
from ..scenes import uniform
from ._common import (
    add_command,
    check_output_file,
    field_input,
    finite_float,
    positive_int,
)
from ._scanning import (
    PRESETS,
    add_scan_pattern_arguments,
    describe,
    make_pattern,
    measured_los,
    plot_scan,
    read_scan_source,
    scan_region,
    scan_source,
)

__all__ = ["PRESETS", "make_pattern", "plot_scan", "register", "run"]


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
    p = add_command(
        sub, "scan", run,
        "a scanning lidar (PPI, RHI, stare, VAD, rosette or a scan file) in a field",
        "Simulate a scanning lidar: a preset or the layout of a Halo .hpl / Windcube "
        ".nc scan file, in a uniform wind or a CFD field; write CF NetCDF (time x "
        "beam x range) and plot the PPI on its cone or the RHI on its plane.",
        epilog="example: lidarjax scan ppi --elevation 3 --n-rays 72 --gates 100 --wind 8,270 "
        "--out ppi.nc --plot ppi.png",
        raw=True)
    p.add_argument("scan", type=scan_source, help=f"a preset ({', '.join(PRESETS)}) or a .hpl / .nc scan file")
    add_scan_pattern_arguments(p, sector=("--start", "--stop"))
    p.add_argument("--point-probe", action="store_true", help="sample gate centres only")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--wind", type=_wind, default=(10.0, 270.0),
                     help="uniform wind 'SPEED,DIRECTION' (m/s, meteorological degrees)")
    src.add_argument("--field", type=field_input, help="a CFD field file (.npz, .nc, ...) instead of --wind")
    p.add_argument("--location", type=_triple, default=(0.0, 0.0, 0.0), help="lidar 'x,y,z' (m)")
    p.add_argument("--beta", type=finite_float, default=0.0, help="mount rotation, degrees")
    p.add_argument("--pitch", type=finite_float, default=0.0, help="degrees (nacelle: -90)")
    p.add_argument("--roll", type=finite_float, default=0.0, help="degrees")
    p.add_argument("--scans", type=positive_int, default=1, help="repetitions flown through time")
    p.add_argument("--out", default="scan.nc", help="CF NetCDF output (default scan.nc)")
    p.add_argument("--plot", default=None,
                   help="PNG of the scan as radar displays draw it (filled gate cells, range rings); "
                        "for a scan file, its own measured Doppler beside the simulated")


def run(args) -> int:
    inputs = [("scan", args.scan), ("--field", args.field)]
    out = check_output_file(args.out, inputs=inputs)
    plot = check_output_file(args.plot, inputs=inputs, option="--plot") if args.plot else None
    pattern, gate, scan_file = read_scan_source(args, with_file=True)
    probe = PointProbe() if args.point_probe else instrument_probe(
        args.instrument or "halo_streamline", gate_length=gate)
    mount = Mount(args.location, beta=args.beta, pitch=args.pitch, roll=args.roll)
    if args.field:
        check_field_file(args.field)
        # an OpenFOAM or VTK mesh: read over the scan's region and exact (its own cellPoint)
        # at every node the scan samples, as `lidarjax simulate --scan`
        field = load_field(args.field, region=scan_region(pattern, mount, probe),
                           exact_at=lambda grid: scan_points(grid, pattern, mount, probe))
    else:
        field = uniform(*args.wind)
    if args.scans > 1:
        res = simulate_scan_series(field, pattern, mount, n_scans=args.scans, probe=probe)
    else:
        res = simulate_scan(field, pattern, mount, probe=probe)
    write_scan_netcdf(out, res.los, azimuth=res.azimuth, elevation=res.elevation, ranges=res.ranges,
                      ray_time=res.times, flags=res.flags, title=f"lidarjax scan {args.scan}")
    print(f"{describe(res, pattern.kind)}; wrote {out}")
    if plot is not None:
        if scan_file is None:
            plot_scan(res, pattern.kind, plot)
        else:  # the file's own Doppler beside the simulation
            los, title = measured_los(scan_file)
            plot_scan(res, pattern.kind, plot, measured=los, measured_title=title)
        print(f"wrote {plot}")
    return 0
