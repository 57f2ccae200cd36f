"""`lidarjax design`: where to put the lidar of a seed settings.dat, found by optimisation
through the forward model (`lidarjax.design_placement`).

One CFD run (the settings' beta, or ``--beta``); the inflow directions are that run's free
stream, or with ``--rotations`` the platform turned about ``--pivot`` (the seed's rotated
platform). Writes the best location as a settings.dat row (``settings_design.dat``), the
correction roses at the start and at the optimum (``roses.csv``), a map of the objective over
the region (``objective_map.csv`` and, with matplotlib, ``design.png``) and prints a summary.
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import time
from pathlib import Path

import numpy as np

from .. import plots
from ..design import (
    RegionBox,
    RegionPolygon,
    design_placement,
    evaluate_placements,
    placement_problem,
)
from ..io import read_settings, write_settings
from ..io.fields import check_field_file, load_field
from ..mount import Mount
from ..progress import LineProgress
from ._common import (
    add_command,
    add_run_arguments,
    add_settings_argument,
    check_output_folder,
    field_paths,
    finite_float,
    make_probe,
    make_scan,
    positive_float,
    positive_int,
    selected_betas,
)
from .sensitivity import parse_std

OUTPUT_FILES = ("settings_design.dat", "roses.csv", "objective_map.csv", "design.png")


def _numbers(text: str, what: str) -> list[float]:
    try:
        values = [float(v) for v in text.replace(" ", "").split(",") if v != ""]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what}: expected numbers separated by commas, got "
                                         f"{text!r}") from None
    if not all(np.isfinite(values)):
        raise argparse.ArgumentTypeError(f"{what}: numbers must be finite, got {text!r}")
    return values


def region_arg(text: str):
    """``box:XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX`` or ``polygon:X1,Y1,X2,Y2,X3,Y3[,...]``."""
    kind, sep, rest = text.partition(":")
    if kind == "box" and sep:
        v = _numbers(rest, "--region box")
        if len(v) != 6:
            raise argparse.ArgumentTypeError(
                f"--region box: expected XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX (6 numbers), got {text!r}")
        return ("box", v)
    if kind == "polygon" and sep:
        v = _numbers(rest, "--region polygon")
        if len(v) < 6 or len(v) % 2:
            raise argparse.ArgumentTypeError(
                f"--region polygon: expected X1,Y1,X2,Y2,X3,Y3[,...] (at least 3 vertices), got "
                f"{text!r}")
        return ("polygon", v)
    raise argparse.ArgumentTypeError(
        f"--region: expected box:XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX or polygon:X1,Y1,X2,Y2,..., got "
        f"{text!r}")


def bounds_arg(text: str):
    v = _numbers(text, "bounds")
    if len(v) != 2 or not v[1] > v[0]:
        raise argparse.ArgumentTypeError(f"expected LOW,HIGH degrees with LOW < HIGH, got {text!r}")
    return tuple(v)


def register(sub) -> None:
    des = add_command(
        sub, "design", run,
        "where to put the lidar: its location (and cone angle, heading) "
        "optimised over all inflow directions through the forward model",
        "Optimise the location of the lidar of a seed settings.dat in a region "
        "(a box, or a polygon at a height above the surface read from the CFD "
        "grid's solid nodes) so that the correction |C_U - 1| and the direction "
        "error (worst case or RMS over directions and heights), or the "
        "installation-uncertainty budget of C_U, are smallest: a coarse grid, then "
        "BFGS through exact gradients from the best candidates, one compiled "
        "program (kept in the compilation cache). Writes settings_design.dat (the "
        "settings with the best location in the beta's row), roses.csv, "
        "objective_map.csv and design.png.",
        epilog="example: lidarjax design settings.dat --field case/ --u-ref 10,0,0 "
        "--region polygon:90,120,102,120,102,134,90,134 --height-above-surface 1 "
        "--objective worst --out design/",
        raw=True)
    add_settings_argument(des, "angles, heights, the lidar's location as the initial guess")
    des.add_argument("--beta", type=finite_float, help="the run's platform rotation (default: "
                                                       "the settings file's beta)")
    add_run_arguments(des, default_scan="windcube_v1")
    des.add_argument("--region", type=region_arg, required=True,
                     help="box:XMIN,XMAX,YMIN,YMAX,ZMIN,ZMAX (CFD m; equal bounds fix a "
                          "coordinate) or polygon:X1,Y1,X2,Y2,X3,Y3,... (with "
                          "--height-above-surface)")
    des.add_argument("--height-above-surface", type=finite_float, default=1.0,
                     help="polygon regions: the lidar's height above the surface, m (default 1)")
    des.add_argument("--objective", choices=("worst", "rms", "uncertainty"), default="worst")
    des.add_argument("--target", choices=("free", "point"), default="free",
                     help="correct to the free stream (--u-ref; default) or to the true wind "
                          "straight above the lidar (the distortion alone, when the inflow "
                          "carries a profile)")
    des.add_argument("--p", type=positive_float, default=8.0,
                     help="worst case: the p-norm surrogate's exponent (default 8)")
    des.add_argument("--direction-weight", type=positive_float, default=0.01,
                     help="weight of one degree of direction error against a unit speed-ratio "
                          "error (default 0.01: 1 deg counts as 1 %%)")
    des.add_argument("--std", action="append", default=[], metavar="NAME=VALUE",
                     help="--objective uncertainty: standard uncertainty of an installation "
                          "input (repeatable), e.g. epsilon=0.5 pitch=0.2")
    des.add_argument("--rotations", default=None,
                     help="platform rotations in degrees (comma list, or START:STOP:STEP) "
                          "about --pivot: the inflow directions seen by the rotated platform")
    des.add_argument("--pivot", default=None, help="X,Y of the platform's rotation axis, CFD m")
    des.add_argument("--weights", default=None,
                     help="wind rose: one weight per rotation (comma list; default uniform)")
    des.add_argument("--min-clearance", type=finite_float, default=0.0,
                     help="metres of fluid required around the lidar (default 0)")
    des.add_argument("--optimise-cone", type=bounds_arg, default=None, metavar="LOW,HIGH",
                     help="also optimise the cone angle within these degrees")
    des.add_argument("--optimise-heading", type=bounds_arg, default=None, metavar="LOW,HIGH",
                     help="also optimise a heading offset (added to gamma) within these degrees")
    des.add_argument("--spacing", type=positive_float, default=None,
                     help="grid spacing for resampling a mesh (OpenFOAM, VTK), m")
    des.add_argument("--n-coarse", type=positive_int, default=64,
                     help="candidates of the coarse stage (default 64)")
    des.add_argument("--n-starts", type=positive_int, default=4,
                     help="local searches from the best candidates (default 4)")
    des.add_argument("--max-steps", type=positive_int, default=60,
                     help="BFGS steps per local search (default 60)")
    des.add_argument("--map", type=positive_int, default=30, metavar="N",
                     help="objective map on N x N points of the region (default 30; 1: none)")
    des.add_argument("--out", default=".", help="output folder (default: .)")


def _rotations(text):
    if text is None:
        return None
    if ":" in text:
        parts = text.split(":")
        try:
            start, stop, step = (float(p) for p in parts)
        except ValueError:
            raise ValueError(f"--rotations {text!r}: expected START:STOP:STEP degrees") from None
        if not step > 0 or not stop > start:
            raise ValueError(f"--rotations {text!r}: need STOP > START and STEP > 0")
        return np.arange(start, stop, step)
    return np.asarray(_numbers(text, "--rotations"))


def _load_box(region, mount_z, heights, cone, margin=5.0):
    """Where the beams of every candidate can look: the region widened by the scan's reach."""
    top = float(np.max(heights))
    reach = top * np.tan(np.deg2rad(min(float(cone), 60.0))) + margin
    if region[0] == "box":
        x0, x1, y0, y1, z0, z1 = region[1]
    else:
        v = np.asarray(region[1]).reshape(-1, 2)
        (x0, y0), (x1, y1) = v.min(0), v.max(0)
        z0, z1 = mount_z - top, mount_z + 2 * margin
    return ([x0 - reach, y0 - reach, z0 - margin], [x1 + reach, y1 + reach, z1 + top + margin])


def run(args) -> int:
    settings = read_settings(args.settings)
    betas = selected_betas(args, settings)
    beta = betas[0]
    location = settings.location(beta)
    paths = field_paths(args, betas)
    check_field_file(paths[beta])
    std = parse_std(args.std) if args.objective == "uncertainty" else None
    if args.std and args.objective != "uncertainty":
        raise ValueError("--std applies to --objective uncertainty; drop it or change the "
                         "objective")
    rotations = _rotations(args.rotations)
    pivot = None if args.pivot is None else _numbers(args.pivot, "--pivot")
    if rotations is not None and (pivot is None or len(pivot) != 2):
        raise ValueError("--rotations need --pivot X,Y (the platform's rotation axis, CFD m)")
    weights = None if args.weights is None else np.asarray(_numbers(args.weights, "--weights"))
    kind, v = args.region
    if kind == "box":
        region = RegionBox((v[0], v[2], v[4]), (v[1], v[3], v[5]))
    else:
        region = RegionPolygon(np.asarray(v).reshape(-1, 2), height=args.height_above_surface)
    scan = make_scan(args.scan, args.cone_angle)
    probe = make_probe(args)
    heights = np.asarray(settings.heights())
    out = check_output_folder(args.out, files=OUTPUT_FILES,
                              inputs=[("settings", args.settings), ("--field", paths[beta])])
    cone = max(float(scan.cone_angle), args.optimise_cone[1] if args.optimise_cone else 0.0)
    lo, hi = _load_box(args.region, float(location[2]), heights, cone)
    if rotations is not None:  # the rotated platform sweeps a disc about the pivot
        r = max(np.hypot(lo[0] - pivot[0], lo[1] - pivot[1]),
                np.hypot(hi[0] - pivot[0], hi[1] - pivot[1]))
        lo[:2] = [pivot[0] - r, pivot[1] - r]
        hi[:2] = [pivot[0] + r, pivot[1] + r]
    meter = LineProgress()
    task = meter.start(3, "lidarjax design", unit="stage")
    t0 = time.perf_counter()
    kw = {} if args.spacing is None else {"spacing": args.spacing}
    field = load_field(paths[beta], region=(lo, hi), **kw)
    meter.update(task, 1, f"field {paths[beta]} loaded ({time.perf_counter() - t0:.1f} s)")
    mount = Mount(location, beta=beta, gamma=settings.gamma, psi=settings.psi,
                  epsilon=settings.epsilon)
    common = dict(u_ref=args.u_ref, rotations=rotations, pivot=pivot, weights=weights,
                  objective=args.objective, target=args.target, p=args.p,
                  direction_weight=args.direction_weight,
                  std=std, min_clearance=args.min_clearance, cone_angle=args.optimise_cone,
                  heading=args.optimise_heading, probe=probe)
    t1 = time.perf_counter()
    res = design_placement(field, scan, mount, heights, region, n_coarse=args.n_coarse,
                           n_starts=args.n_starts, max_steps=args.max_steps, **common)
    meter.update(task, 2, f"search ({res.n_evaluations} evaluations, "
                          f"{time.perf_counter() - t1:.1f} s with compilation)")
    if not res.feasible:
        meter.close(task)
        raise ValueError(f"no feasible location in --region: {res.message}")
    grid_xy = grid_values = None
    if args.map > 1:
        lo_r, hi_r = region.bounds()
        axes = [np.linspace(lo_r[i], hi_r[i], args.map) for i in range(min(2, len(lo_r)))]
        mesh = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, len(axes))
        problem = placement_problem(field, scan, mount, heights, region, **common)[0]
        rest = np.broadcast_to(res.x[len(axes):], (mesh.shape[0], res.x.size - len(axes)))
        grid_xy = mesh
        grid_values, _ = evaluate_placements(problem, np.concatenate([mesh, rest], axis=1))
    meter.update(task, 3, "map")
    meter.close(task)
    _write(out, args, settings, beta, res, grid_xy, grid_values, region)
    print(f"best location ({', '.join(res.names)}): "
          f"{', '.join(f'{x:.3f}' for x in res.x)}; lidar at "
          f"({', '.join(f'{c:.3f}' for c in res.location)}) m")
    print(f"objective ({args.objective}): {res.value:.6g} (start {res.start_value:.6g}); "
          f"gradient {np.array2string(res.gradient, precision=3)}; "
          f"{'converged' if res.converged else res.message}")
    if np.isfinite(res.worst):
        print(f"worst |error| {res.worst:.4g}, RMS {res.rms:.4g} over directions and heights")
    print(f"{res.n_evaluations} objective evaluations ({res.n_forward} forward simulations); "
          f"wrote {out}")
    return 0


def _write(out: Path, args, settings, beta, res, grid_xy, grid_values, region):
    out.mkdir(parents=True, exist_ok=True)
    locations = np.array(settings.locations, dtype=np.float64, copy=True)
    k = int(np.argmin(np.abs(np.asarray(settings.betas, np.float64) - beta)))
    locations[k] = res.location
    write_settings(out / "settings_design.dat", dataclasses.replace(settings, locations=locations))
    with open(out / "roses.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(["direction_deg", "h_m", "cff_U_start", "cff_th_start_deg", "cff_U",
                    "cff_th_deg"])
        d = np.asarray(res.rose.directions)
        heights = np.asarray(settings.heights())
        for i in range(d.size):
            for j, h in enumerate(heights):
                w.writerow([f"{d[i]:.6g}", f"{h:.6g}",
                            f"{float(res.rose_start.speed_ratio[i, j]):.8g}",
                            f"{float(res.rose_start.direction_addend[i, j]):.8g}",
                            f"{float(res.rose.speed_ratio[i, j]):.8g}",
                            f"{float(res.rose.direction_addend[i, j]):.8g}"])
    xy = res.coarse[:, :2] if grid_xy is None else grid_xy
    vals = res.coarse_values if grid_values is None else grid_values
    with open(out / "objective_map.csv", "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow([*res.names[:xy.shape[1]], f"objective_{args.objective}"])
        for row, val in zip(xy, vals, strict=True):
            w.writerow([*(f"{c:.6g}" for c in row), f"{val:.8g}"])
    try:
        outline = np.asarray(region.vertices) if isinstance(region, RegionPolygon) else None
        plots.plot_design(res, out / "design.png", grid_xy=xy, grid_values=vals,
                          outline=outline, title=f"lidarjax design: {args.objective}")
    except ImportError:  # matplotlib is an optional extra
        pass
