"""`lidarjax farm`: a lidar among wind turbines, swept over inflow directions.

Reads seed 004 layout files and turbine types, builds a `lidarjax.scenes.WindFarm`, simulates
a ground lidar (``--lidar X Y Z``) or a nacelle lidar on one turbine (``--nacelle NAME``) for
every direction, and writes to ``--out``:

- ``roses.png``: correction roses (free stream / lidar) with the IEC 61400-12-1 Annex A
  disturbed sectors shaded;
- ``map.png``: the hub-height wake field at ``--map-direction`` with turbines, lidar, beams;
- ``directions.csv``: per direction, disturbed or not, lidar speed/direction, correction
  factors per height;
- ``yaw_gradient.csv``: d(lidar speed at the first height)/d(yaw) of every turbine, m/s per
  degree, per direction (0 for turbines whose wake misses the beams);
- ``sectors.csv``: each turbine's bearing, distance and excluded width; the merged sectors;
- ``probes.csv``, ``lidarProbes`` (OpenFOAM ``probes`` dictionary), ``lidarProbes_zcfd.py``
  (zCFD ``turb_probe``, seed 004): the lidar's sample points at ``--map-direction`` (named
  ``lidar_h<height>_beam<b>_q<node>``, as `lidarjax monitor-points` writes them) plus each turbine's
  hub centre (``<name>_hub``) and seed 004's reference point 1 D upstream at hub height
  (``<name>_ref1D``);
- ``table.npz``: the response table (for ``lidarjax correct``).

The study is `lidarjax.farm_study` and the files `lidarjax.write_farm_study`
(`lidarjax.workflows.farm_study`); this module parses, validates the options and prints.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import numpy as np

from ..io.layout import read_farm
from ..workflows.farm_study import (
    FARM_SCANS,
    FarmStudyConfig,
    check_lidar_position,
    farm_study,
    write_farm_study,
)
from ._common import (
    add_command,
    finite_float,
    input_file,
    positive_float,
)

SCANS = FARM_SCANS


def _directions(text: str):
    try:
        parts = [float(p) for p in text.split(":")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected START:STOP:STEP degrees, got {text!r}") from None
    if len(parts) != 3 or parts[2] <= 0 or parts[1] <= parts[0]:
        raise argparse.ArgumentTypeError(
            f"expected START:STOP:STEP degrees with STOP > START and STEP > 0, got {text!r}")
    d = np.arange(parts[0], parts[1] - 1e-9, parts[2])
    if np.unique(np.mod(np.round(d, 9), 360.0)).size != d.size:
        raise argparse.ArgumentTypeError(f"directions {text!r} repeat modulo 360")
    return d


def _floats(text: str):
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def register(sub) -> None:
    p = add_command(
        sub, "farm", run,
        "a lidar among wind turbines: wakes, correction roses, disturbed sectors",
        "Simulate a ground or nacelle lidar in a wind farm's wakes for every inflow "
        "direction; write correction roses with the IEC disturbed sectors shaded, a "
        "wake map, per-direction tables, yaw gradients and probe points.",
        epilog="example: lidarjax farm farm.txt --turbine nrel5mw.csv --lidar 252000 646300 0 "
        "--scan windcube_v2 --speed 10 --directions 0:360:2 --out farm_out")
    p.add_argument("layouts", nargs="+", type=input_file,
                   help="layout file(s): '<name> <easting> <northing>' lines")
    p.add_argument("--turbine", action="append", required=True, type=input_file,
                   help="turbine type CSV (# rotor_diameter, # hub_height, speed,ct columns); "
                        "once for all layouts or once per layout")
    where = p.add_mutually_exclusive_group(required=True)
    where.add_argument("--lidar", nargs=3, type=finite_float, metavar=("X", "Y", "Z"),
                       help="ground lidar position, CFD/UTM metres (Z: the lidar's height "
                            "above the ground datum)")
    where.add_argument("--nacelle", metavar="NAME",
                       help="nacelle lidar on this turbine (hub height, yawed with it)")
    p.add_argument("--backward", action="store_true",
                   help="nacelle lidar looking downstream into its own wake")
    p.add_argument("--scan", choices=SCANS, default=None,
                   help="default windcube_v2 (ground) or nacelle_2beam (nacelle)")
    p.add_argument("--cone-angle", type=positive_float, default=None,
                   help="cone (ground) or half-angle (nacelle) in degrees (default: the scan's)")
    p.add_argument("--heights", type=_floats, default=None,
                   help="measurement heights above the lidar (ground; default: the mean hub "
                        "height) or distances along the axis (nacelle; default 2.5 D), m")
    p.add_argument("--speed", type=positive_float, default=10.0, help="free stream at hub height, m/s")
    p.add_argument("--directions", type=_directions, default=_directions("0:360:2"),
                   help="START:STOP:STEP meteorological degrees (default 0:360:2)")
    p.add_argument("--shear", type=finite_float, default=0.0, help="power-law exponent (default 0)")
    p.add_argument("--model", choices=("gaussian", "top_hat"), default="gaussian",
                   help="wake model (default gaussian: smooth in direction)")
    p.add_argument("--combination", choices=("sum_of_squares", "linear", "max"),
                   default="sum_of_squares")
    p.add_argument("--expansion", type=positive_float, default=None,
                   help="wake expansion k (default 0.05 top hat, 0.0325 gaussian)")
    p.add_argument("--yaw", action="append", default=[], metavar="NAME=DEG",
                   help="yaw misalignment of a turbine, degrees (repeatable)")
    p.add_argument("--probe", choices=("point", "pulsed", "cw"), default="pulsed",
                   help="probe volume (default pulsed)")
    p.add_argument("--map-direction", type=finite_float, default=None,
                   help="direction of the wake map and probe points (default: the direction "
                        "with the largest speed correction)")
    p.add_argument("--out", required=True, help="output folder (created)")


def run(args) -> int:
    lay = read_farm(args.layouts, args.turbine)
    names = list(lay.names)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a folder")
    if not (args.speed > 0 and np.isfinite(args.speed)):
        raise ValueError(f"--speed must be positive m/s, got {args.speed}")
    yaw = {}
    for item in args.yaw:
        name, _, value = item.partition("=")
        if name not in names:
            raise ValueError(f"--yaw {item!r}: no turbine named {name!r}")
        try:
            yaw[name] = float(value)
        except ValueError:
            raise ValueError(f"--yaw {item!r}: expected NAME=DEGREES") from None
        if abs(yaw[name]) >= 90:
            raise ValueError(f"--yaw {item!r}: |yaw| must be below 90 degrees")
    nacelle = args.nacelle is not None
    if nacelle and args.nacelle not in names:
        raise ValueError(f"--nacelle {args.nacelle!r}: no turbine of that name in the layouts")
    if args.backward and not nacelle:
        raise ValueError("--backward needs --nacelle")
    scan_name = args.scan or ("nacelle_2beam" if nacelle else "windcube_v2")
    if nacelle != scan_name.startswith("nacelle"):
        raise ValueError(f"--scan {scan_name} is a {'nacelle' if not nacelle else 'ground'} "
                         f"lidar; use {'--nacelle NAME' if not nacelle else 'a nacelle_* scan'}")
    if not nacelle:
        check_lidar_position(lay, args.lidar)
    if args.heights is not None and (not args.heights or any(not (h > 0) for h in args.heights)):
        raise ValueError(f"--heights must be positive metres, got {args.heights}")

    config = FarmStudyConfig(
        lidar=args.lidar, nacelle=args.nacelle, backward=args.backward, scan=scan_name,
        cone_angle=args.cone_angle, heights=args.heights, directions=args.directions,
        speed=args.speed, shear=args.shear, model=args.model, combination=args.combination,
        expansion=args.expansion, yaw=yaw, probe=args.probe, map_direction=args.map_direction)
    study = farm_study(lay, config=config)
    study = dataclasses.replace(study, layouts=tuple(args.layouts))
    write_farm_study(out, study)
    n_dist = int(study.disturbed.sum())
    top = int(np.argmax(np.abs(study.yaw_gradient[study.map_index or 0])))
    print(f"farm: {len(names)} turbines, {study.directions.size} directions ({n_dist} in "
          f"disturbed sectors), {study.kind}; largest correction {study.largest_correction:.3f} "
          f"at {study.map_direction:g} deg, where {names[top]}'s yaw moves the reading most "
          f"-> {out}")
    return 0
