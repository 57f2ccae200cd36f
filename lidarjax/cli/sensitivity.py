"""`lidarjax sensitivity`: installation uncertainty budgets of a seed settings.dat's lidar,
for every platform rotation in one compiled batch.

The budgets are `lidarjax.sensitivity_report` and the files `lidarjax.write_sensitivity_report`
(`lidarjax.workflows.sensitivity_report`); this module parses, validates and prints.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import read_settings
from ..io.seed_output import format_number
from ..sensitivity import INPUTS, OUTPUTS
from ..workflows.sensitivity_report import sensitivity_report, write_sensitivity_report
from ._common import (
    add_command,
    add_run_arguments,
    add_settings_argument,
    field_paths,
    make_probe,
    make_scan,
    positive_float,
    tilt_angle,
)

DEFAULT_OUTPUTS = "lidar_speed,lidar_direction,cff_U,cff_th"


def register(sub) -> None:
    sen = add_command(
        sub, "sensitivity", run,
        "uncertainty budgets of the lidar's outputs from installation "
        "uncertainties (GUM through exact gradients)",
        "For every platform rotation (beta row) of a seed settings.dat, in one "
        "compiled batch: the Jacobians of the lidar's outputs with respect to the "
        "installation inputs given with --std, the combined standard uncertainty "
        "per height (GUM law of propagation) and each input's contribution. Prints "
        "a budget table per beta and height, writes one CSV per output and plots "
        "(budget bars per height, sensitivity profiles against z/H).",
        epilog="example: lidarjax sensitivity settings.dat --field 'runs/platform_{beta}.npz' "
        "--std epsilon=0.5 --std pitch=0.2 --std roll=0.2 --std location=0.05 "
        "--out budget/\n\ninputs: location (or x, y, z; m), beta, gamma, psi, epsilon, "
        "pitch, roll, cone_angle (deg), heights (m), speed (m/s of the free stream)",
        raw=True)
    add_settings_argument(sen, "all beta rows are used")
    add_run_arguments(sen, default_scan="windcube_v2")
    sen.add_argument("--std", action="append", default=[], metavar="NAME=VALUE",
                     help="standard uncertainty of an input, in its unit (repeatable): e.g. "
                          "epsilon=0.5 (deg), pitch=0.2 (deg), location=0.05 (m, or three "
                          "values x,y,z: location=0.05,0.05,0.1)")
    sen.add_argument("--outputs", default=DEFAULT_OUTPUTS,
                     help=f"comma-separated outputs (default {DEFAULT_OUTPUTS}); also lidar_u, "
                          "lidar_v, lidar_w, cff_u, cff_v, cff_w, point_speed, cfp_U, cfp_th")
    sen.add_argument("--pitch", type=tilt_angle, default=0.0, help="nominal pitch, deg (default 0)")
    sen.add_argument("--roll", type=tilt_angle, default=0.0, help="nominal roll, deg (default 0)")
    sen.add_argument("--tilt-compensation", action="store_true",
                     help="the instrument compensates its tilt")
    sen.add_argument("--n-monte-carlo", type=int, default=0,
                     help="also a Monte Carlo of N samples per beta to check the linear "
                          "budget (5000 gives the standard uncertainty to about 1 %%)")
    sen.add_argument("--ref-height", type=positive_float, default=None,
                     help="H of z/H, m (default: the lidar's mean z, i.e. its height above "
                          "the CFD z = 0)")
    sen.add_argument("--out", default=".", help="output folder (default: .)")
    sen.add_argument("--no-plots", action="store_true", help="skip the figures")


def parse_std(items) -> dict:
    """``["epsilon=0.5", "location=0.05,0.05,0.1"]`` -> ``{"epsilon": 0.5, "location":
    (0.05, 0.05, 0.1)}``; raises `ValueError` (one line) for anything else."""

    if not items:
        raise ValueError("give at least one --std NAME=VALUE (e.g. --std epsilon=0.5)")
    allowed = sorted(set(INPUTS) - {"direction"} | {"location"})
    std: dict = {}
    for item in items:
        name, sep, text = item.partition("=")
        name = name.strip()
        if not sep or not name:
            raise ValueError(f"--std {item!r}: expected NAME=VALUE, e.g. epsilon=0.5")
        if name not in allowed:
            raise ValueError(f"--std {item!r}: unknown input {name!r}; choose from "
                             f"{', '.join(allowed)}")
        try:
            values = tuple(float(v) for v in text.split(","))
        except ValueError:
            raise ValueError(f"--std {item!r}: {text!r} is not a number") from None
        want = 3 if name == "location" else 1
        if len(values) not in (1, want):
            raise ValueError(f"--std {item!r}: {name} takes {'1 or 3 values' if want == 3 else 'one value'}")
        if not all(np.isfinite(v) and v >= 0 for v in values):
            raise ValueError(f"--std {item!r}: standard uncertainties must be finite and >= 0")
        if name in std:
            raise ValueError(f"--std {name} is given twice")
        std[name] = values[0] if len(values) == 1 else values
    return std


def run(args) -> int:
    std = parse_std(args.std)
    outputs = tuple(o.strip() for o in args.outputs.split(",") if o.strip())
    bad = [o for o in outputs if o not in OUTPUTS or o in ("los", "lidar_velocity", "inv_speed",
                                                           "inv_direction")]
    if bad or not outputs:
        raise ValueError(f"--outputs: unknown or not per-height output(s) {bad}; choose from "
                         f"{DEFAULT_OUTPUTS}, lidar_u, lidar_v, lidar_w, cff_u, cff_v, cff_w, "
                         f"point_speed, point_direction, cfp_u, cfp_v, cfp_w, cfp_U, cfp_th")
    if args.n_monte_carlo < 0 or args.n_monte_carlo == 1:
        raise ValueError(f"--n-monte-carlo must be 0 or at least 2, got {args.n_monte_carlo}")
    if args.ref_height is not None and not args.ref_height > 0:
        raise ValueError(f"--ref-height must be positive (m), got {args.ref_height}")
    for name, v in (("--pitch", args.pitch), ("--roll", args.roll)):
        if not np.isfinite(v):
            raise ValueError(f"{name} must be a finite angle in degrees, got {v}")
    settings = read_settings(args.settings)
    betas = [float(b) for b in settings.betas]
    paths = field_paths(args, betas)
    scan = make_scan(args.scan, args.cone_angle, tilt_compensation=bool(args.tilt_compensation))
    probe = make_probe(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    report = sensitivity_report(settings, [paths[b] for b in betas], std=std, betas=betas,
                                scan=scan, probe=probe, u_ref=args.u_ref, outputs=outputs,
                                pitch=args.pitch, roll=args.roll,
                                n_monte_carlo=args.n_monte_carlo, ref_height=args.ref_height)
    for k, b in enumerate(betas):
        print(f"== beta = {b:g} deg ({paths[b].name}) ==")
        print(report.budget.table(sector=k))
        print()
    meta = {"settings": str(args.settings), "field": args.field, "scan": args.scan,
            "probe": args.probe}
    written = write_sensitivity_report(out, report, plots=not args.no_plots, metadata=meta)
    print("largest standard uncertainty over betas and heights: " + ", ".join(
        f"{o} {v:.3g} {OUTPUTS[o]}" for o, v in report.largest.items()))
    print(f"wrote {len(written)} file(s) to {out} (betas: "
          f"{', '.join(format_number(b) for b in betas)})")
    return 0
