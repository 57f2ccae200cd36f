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
"""

from __future__ import annotations

import argparse
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import scan as scans
from .._util import atomic_write_text
from ..angles import heading
from ..batch import simulate_rotations
from ..disturbed_sectors import disturbed_sectors, in_sectors, merge_sectors
from ..forward import simulate
from ..io.layout import read_farm
from ..io.monitor_points import (
    MonitorPoints,
    write_monitor_points_csv,
    write_openfoam_probes,
    write_zcfd_probes,
)
from ..io.tables import save_table
from ..mount import Mount
from ..plots import plot_farm_map, plot_roses
from ..probe import CWProbe, PulsedProbe
from ..response import ResponseTable
from ..scenes.farm import nacelle_mount
from ..workflows.monitor_points import monitor_points
from ._common import finite_float, positive_float

SCANS = ("windcube_v1", "windcube_v2", "zephir", "nacelle_2beam", "nacelle_4beam")


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
    p = sub.add_parser(
        "farm", help="a lidar among wind turbines: wakes, correction roses, disturbed sectors",
        description="Simulate a ground or nacelle lidar in a wind farm's wakes for every inflow "
                    "direction; write correction roses with the IEC disturbed sectors shaded, a "
                    "wake map, per-direction tables, yaw gradients and probe points.",
        epilog="example: lidarjax farm farm.txt --turbine nrel5mw.csv --lidar 252000 646300 0 "
               "--scan windcube_v2 --speed 10 --directions 0:360:2 --out farm_out")
    p.add_argument("layouts", nargs="+", help="layout file(s): '<name> <easting> <northing>' lines")
    p.add_argument("--turbine", action="append", required=True,
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
    p.set_defaults(func=run)


def _check_lidar(lay, xyz) -> None:
    d = np.hypot(lay.easting - xyz[0], lay.northing - xyz[1])
    r = 0.5 * lay.diameter
    inside = (d < r) & (xyz[2] > lay.hub_height - r - 1e-9) & (xyz[2] < lay.hub_height + r)
    inside |= d < 0.5  # standing on the tower
    if inside.any():
        k = int(np.argmax(inside))
        raise ValueError(f"the lidar at ({xyz[0]:g}, {xyz[1]:g}, {xyz[2]:g}) is inside turbine "
                         f"{lay.names[k]}'s rotor ({d[k]:.1f} m from its tower, rotor radius "
                         f"{r[k]:g} m, hub {lay.hub_height[k]:g} m)")
    under = d < r
    if under.any():
        k = int(np.argmax(under))
        raise ValueError(f"the lidar is inside turbine {lay.names[k]}'s rotor footprint "
                         f"({d[k]:.1f} m from its tower, rotor radius {r[k]:g} m): its beams "
                         f"would cross the blades")


def run(args) -> int:
    lay = read_farm(args.layouts, args.turbine)
    names = list(lay.names)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"--out {out} exists and is not a folder")
    if not (args.speed > 0 and np.isfinite(args.speed)):
        raise ValueError(f"--speed must be positive m/s, got {args.speed}")
    yaw = np.zeros(len(names))
    for item in args.yaw:
        name, _, value = item.partition("=")
        if name not in names:
            raise ValueError(f"--yaw {item!r}: no turbine named {name!r}")
        try:
            yaw[names.index(name)] = float(value)
        except ValueError:
            raise ValueError(f"--yaw {item!r}: expected NAME=DEGREES") from None
        if abs(yaw[names.index(name)]) >= 90:
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
    make = getattr(scans, scan_name)
    scan = make() if args.cone_angle is None else make(args.cone_angle)
    if not nacelle:
        _check_lidar(lay, args.lidar)
    k_nac = names.index(args.nacelle) if nacelle else None
    if args.heights is None:
        heights = [2.5 * float(lay.diameter[k_nac])] if nacelle else [float(np.mean(lay.hub_height))]
    else:
        heights = args.heights
    if not heights or any(not (h > 0) for h in heights):
        raise ValueError(f"--heights must be positive metres, got {heights}")
    probe = {"point": None, "pulsed": PulsedProbe(), "cw": CWProbe()}[args.probe]

    farm = lay.to_farm(speed=args.speed, direction=float(args.directions[0]), alpha=args.shear,
                       model=args.model, combination=args.combination,
                       expansion=args.expansion, yaw=yaw)
    origin = np.asarray(farm.origin, np.float64) + np.asarray(farm.origin_lo, np.float64)
    dirs = np.asarray(args.directions, np.float64)
    hts = jnp.asarray(heights, farm.dtype)
    ground = None if nacelle else Mount(np.asarray(args.lidar, np.float64))

    def at(direction, yaw_deg=None):
        f = eqx.tree_at(lambda g: g.direction, farm, jnp.asarray(direction, farm.dtype))
        if yaw_deg is not None:
            f = eqx.tree_at(lambda g: g.yaw, f, yaw_deg)
        m = nacelle_mount(f, k_nac, backward=args.backward, north=True) if nacelle else ground
        return f, m

    def reading(direction, yaw_deg):
        f, m = at(direction, yaw_deg)
        return simulate(f, scan, m, hts, probe=probe, point_reference=False).lidar_speed[0]

    run_dirs = dirs if args.map_direction is None else np.append(dirs, args.map_direction)
    stacked = jax.vmap(lambda d: at(d)[0])(jnp.asarray(run_dirs, farm.dtype))
    mounts = jax.vmap(lambda f: nacelle_mount(f, k_nac, backward=args.backward, north=True))(stacked) \
        if nacelle else ground
    u_refs = args.speed * np.stack([np.asarray(heading(d)) for d in run_dirs])
    sims_all = simulate_rotations(stacked, scan, mounts, hts, u_refs=u_refs, probe=probe,
                                point_reference=False)
    sims = jax.tree_util.tree_map(lambda a: a[: dirs.size], sims_all)
    grad_yaw = np.asarray(jax.jit(jax.vmap(jax.grad(reading, argnums=1), in_axes=(0, None)))(
        jnp.asarray(dirs, farm.dtype), farm.yaw))

    ratio = np.asarray(sims.cff_U, np.float64)
    addend = np.asarray(sims.cff_th, np.float64)
    speed = np.asarray(sims.lidar_speed, np.float64)
    ldir = np.asarray(sims.lidar_direction, np.float64)

    loc_xy = (np.asarray(farm.hub_points()[k_nac], np.float64)[:2] + origin[:2]) if nacelle \
        else np.asarray(args.lidar[:2])
    secs = disturbed_sectors(loc_xy, lay.easting, lay.northing, lay.diameter, names)
    merged = merge_sectors(secs)
    disturbed = in_sectors(dirs, merged)

    out.mkdir(parents=True, exist_ok=True)
    labels = [f"{h:g} m" for h in heights]
    kind = f"nacelle lidar on {args.nacelle}" if nacelle else "ground lidar"
    plot_roses(dirs, ratio, addend, labels, out / "roses.png", shade=merged,
               title=f"{scan_name} {kind}, {args.model} wakes, {args.speed:g} m/s")

    k_map = int(np.nanargmax(np.abs(ratio[:, 0] - 1.0))) if args.map_direction is None else None
    map_dir = float(dirs[k_map]) if k_map is not None else float(args.map_direction)
    f_map, m_map = at(map_dir)
    pts_abs = np.asarray(sims_all.points[k_map if k_map is not None else -1], np.float64)  # (h, b, 3)
    m_loc = np.asarray(m_map.location, np.float64) + np.asarray(m_map.location_lo, np.float64)
    lidar_local = m_loc - origin
    beams = np.stack([np.broadcast_to(lidar_local[:2], pts_abs[-1, :, :2].shape),
                      pts_abs[-1, :, :2] - origin[:2]], 1)
    plot_farm_map(f_map, float(np.mean(lay.hub_height)), out / "map.png", names=names,
                  lidar=lidar_local[:2], beams=beams,
                  title=f"{args.model} wakes from {map_dir:g} deg at hub height, {kind}")

    def fmt(x):
        return "" if not np.isfinite(x) else f"{x:.6g}"

    head = ["direction_deg", "disturbed"]
    for h in heights:
        head += [f"lidar_speed_{h:g}m", f"lidar_direction_{h:g}m", f"speed_ratio_{h:g}m",
                 f"direction_addend_{h:g}m"] + ([f"yaw_misalignment_{h:g}m"] if nacelle else [])
    # a nacelle lidar reports (north=True) true directions; its yaw misalignment is the
    # reported direction minus the bearing its axis points to (rotor heading, +180 backward)
    axis = (dirs - yaw[k_nac] + (180.0 if args.backward else 0.0)) if nacelle else None
    rows = [",".join(head)]
    for i, d in enumerate(dirs):
        row = [f"{d:g}", str(int(disturbed[i]))]
        for j in range(len(heights)):
            row += [fmt(speed[i, j]), fmt(ldir[i, j]), fmt(ratio[i, j]), fmt(addend[i, j])]
            if nacelle:
                row.append(fmt(float(np.mod(ldir[i, j] - axis[i] + 180.0, 360.0) - 180.0)))
        rows.append(",".join(row))
    meta = (f"# lidarjax farm: {kind} ({scan_name}), {args.model} wakes, {args.combination}, "
            f"free stream {args.speed:g} m/s at hub height, shear {args.shear:g}; speed_ratio = "
            f"free / lidar, direction_addend = free - lidar (deg); disturbed: IEC 61400-12-1 A\n")
    atomic_write_text(out / "directions.csv", meta + "\n".join(rows) + "\n")

    rows = ["direction_deg," + ",".join(names)]
    rows += [f"{d:g}," + ",".join(f"{g:.6g}" for g in grad_yaw[i]) for i, d in enumerate(dirs)]
    atomic_write_text(out / "yaw_gradient.csv",
                      f"# d(lidar speed at {heights[0]:g} m)/d(yaw of each turbine), m/s per "
                      f"degree (yaw positive anticlockwise seen from above)\n" + "\n".join(rows) + "\n")

    rows = ["name,bearing_deg,distance_m,diameter_m,excluded_width_deg,considered,too_close"]
    rows += [f"{s.name},{s.bearing:.3f},{s.distance:.2f},{s.diameter:g},{s.width:.3f},"
             f"{int(s.considered)},{int(s.too_close)}" for s in secs]
    rows += ["", "merged_start_deg,merged_end_deg"] + [f"{a:.3f},{b:.3f}" for a, b in merged]
    atomic_write_text(out / "sectors.csv", "\n".join(rows) + "\n")

    hub = np.asarray(f_map.hub_points(), np.float64) + origin
    ref = np.asarray(f_map.reference_points(), np.float64) + origin
    locs = farm_probe_locations(names, hub, ref, lay.hub_height, scan, m_map, heights, probe)
    meta = {"direction_deg": map_dir, "rows": "lidar beam points (quadrature nodes with "
            "--probe pulsed/cw), then turbine hub centres and seed 004 reference points 1 D "
            "upstream at hub height (beam/node -3)"}
    write_monitor_points_csv(out / "probes.csv", locs, metadata=meta)
    write_openfoam_probes(out / "lidarProbes", locs, metadata=meta)
    write_zcfd_probes(out / "lidarProbes_zcfd.py", locs, metadata=meta)
    if dirs.size >= 3:
        table = ResponseTable.from_simulations(sims, mount=None)
        save_table(out / "table.npz", table, {"scan": scan_name, "layouts": list(args.layouts),
                                              "model": args.model, "speed": args.speed})
    n_dist = int(disturbed.sum())
    top = int(np.argmax(np.abs(grad_yaw[k_map if k_map is not None else 0])))
    print(f"farm: {len(names)} turbines, {dirs.size} directions ({n_dist} in disturbed sectors), "
          f"{kind}; largest correction {np.nanmax(np.abs(ratio - 1)):.3f} at {map_dir:g} deg, "
          f"where {names[top]}'s yaw moves the reading most -> {out}")
    return 0


def farm_probe_locations(names, hub, ref, hub_height, scan, mount, heights, probe):
    """The lidar's probe points (`lidarjax.monitor_points`, label ``lidar``) followed by each
    turbine's hub centre and reference point (absolute CFD metres) as one `MonitorPoints`;
    turbine rows have ``beam = node = -3``, NaN beta and weight, height = hub height."""

    lidar = monitor_points(scan, mount, np.asarray(heights, np.float64), probe,
                            labels=["lidar"])
    n = 2 * len(names)
    turbines = MonitorPoints(
        names=tuple(f"{x}_hub" for x in names) + tuple(f"{x}_ref1D" for x in names),
        mount=("turbines",) * n, points=np.concatenate([hub, ref]),
        beta=np.full(n, np.nan), height=np.tile(np.asarray(hub_height, np.float64), 2),
        beam=np.full(n, -3), node=np.full(n, -3), weight=np.full(n, np.nan))
    both = {f: (getattr(lidar, f) + getattr(turbines, f)) if f in ("names", "mount")
            else np.concatenate([getattr(lidar, f), getattr(turbines, f)])
            for f in ("names", "mount", "points", "beta", "height", "beam", "node", "weight")}
    return MonitorPoints(**both)
