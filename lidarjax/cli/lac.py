"""`lidarjax lac`: lidar-assisted control of a turbine with a nacelle or spinner lidar: the
analytic lidar–rotor spectra, coherence, coherence bandwidth, feed-forward filter cut-off,
filter delay and buffer time (`lidarjax.control`), pictures of ``gamma^2`` and ``|G_RL|`` and
of the scan on the rotor disc, and with ``--design`` the scan with the widest coherence
bandwidth (`lidarjax.design.design_lac_scan`).
"""

from __future__ import annotations

import argparse
import json

import numpy as np

from .. import control as lc
from .._util import import_optional
from ..design import control as dc
from ..probe import CWProbe, PulsedProbe
from ._common import check_output_folder, finite_float, positive_float, positive_int

FILES = ("lac_spectra.csv", "lac_summary.json", "lac_coherence.png", "lac_disc.png")


def register(sub) -> None:
    p = sub.add_parser(
        "lac", help="lidar-assisted control: lidar–rotor coherence, filter and buffer time, scan design",
        description="The analytic spectra of the rotor-effective wind speed and of a lidar's estimate "
                    "of it (IEC Kaimal turbulence with the IEC coherence, Task 52's model, or with "
                    "--inflow mann the Mann (1994) spectral tensor of lidarjax's boxes), their "
                    "coherence and transfer function, the coherence bandwidth, the -3 dB cut-off of a "
                    "first-order feed-forward filter, its delay and the buffer time. With --design: "
                    "the half-cone angle (and gate length of a pulsed lidar) with the widest bandwidth.",
        epilog="example: lidarjax lac --turbine IEA15MW --speed 18 --lidar pulsed --beams 4 "
               "--distance 160 --half-cone 19.2 --out lac/",
        formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--turbine", default="IEA15MW", choices=sorted(dc.TURBINES), help="turbine preset")
    p.add_argument("--radius", type=positive_float, help="rotor radius, m (default: the preset's)")
    p.add_argument("--speed", type=positive_float, help="mean wind speed, m/s (default: rated)")
    p.add_argument("--turbulence-class", default="B", choices=sorted(lc.IEC_REFERENCE_INTENSITY),
                   help="IEC turbulence class (default B)")
    p.add_argument("--ti", type=positive_float, help="turbulence intensity sigma_u/U (overrides the class)")
    p.add_argument("--length-scale", type=positive_float, default=42.0, help="IEC Lambda_1, m (default 42)")
    p.add_argument("--inflow", default="kaimal", choices=("kaimal", "mann"),
                   help="turbulence model: IEC Kaimal spectra with the IEC coherence (Task 52's model), "
                        "or the Mann spectral tensor, its level from --ti (or the class) unless "
                        "--alphaepsilon (default kaimal)")
    p.add_argument("--mann-length-scale", type=positive_float,
                   help="Mann's L, m (default 0.7 Lambda_1: 29.4 m, IEC 61400-1 Annex C); --inflow mann only")
    p.add_argument("--gamma", type=finite_float,
                   help="Mann's shear anisotropy Gamma, >= 0 (default 3.9, IEC); --inflow mann only")
    p.add_argument("--alphaepsilon", type=positive_float,
                   help="Mann's spectral level alpha eps^(2/3), m^(4/3)/s^2 (default: the level whose "
                        "sigma_u is --ti times the speed); --inflow mann only")
    p.add_argument("--mann-nodes", type=positive_int,
                   help="Gauss-Legendre nodes per lateral and vertical wavenumber axis, >= 4 (default 96; "
                        "fewer is faster and coarser, see MannInflow); --inflow mann only")
    p.add_argument("--lidar", default="pulsed", choices=("pulsed", "cw"), help="range weighting")
    p.add_argument("--beams", type=positive_int, default=4, help="beams or scan points on the cone (default 4)")
    p.add_argument("--distance", type=positive_float, default=160.0, help="focus distance upstream, m")
    p.add_argument("--half-cone", type=positive_float, default=19.2, help="half-cone angle, deg")
    p.add_argument("--gate", type=positive_float, default=30.0, help="pulsed range gate, m (default 30)")
    p.add_argument("--scan-time", type=positive_float, default=1.0, help="one full scan, s (default 1)")
    p.add_argument("--prediction-time", type=float, default=2.0,
                   help="tau, how far ahead the pitch must act, s (default 2)")
    p.add_argument("--grid", type=positive_float, default=8.0, help="rotor grid spacing, m (default 8)")
    p.add_argument("--fmax", type=positive_float, default=0.5, help="highest frequency, Hz (default 0.5)")
    p.add_argument("--nf", type=positive_int, default=500, help="number of frequencies (default 500)")
    p.add_argument("--design", action="store_true",
                   help="optimise the half-cone angle (5-40 deg) and, pulsed, the gate (10-80 m)")
    p.add_argument("--out", help="folder for lac_spectra.csv, lac_summary.json and the pictures")
    p.set_defaults(func=run)


def _inputs(args):
    turbine = dc.TURBINES[args.turbine]
    radius = args.radius or turbine.radius
    speed = args.speed or turbine.rated_speed
    ti = args.ti if args.ti is not None else float(lc.iec_turbulence_intensity(speed, args.turbulence_class))
    if args.nf < 2:
        raise ValueError("--nf must be at least 2 frequencies")
    inflow = _mann(args, speed, ti) if args.inflow == "mann" else lc.KaimalInflow(speed, ti, args.length_scale)
    level_ti = None if args.inflow == "mann" and args.alphaepsilon else ti
    return dc.Turbine(radius, turbine.hub_height, turbine.rated_speed), inflow, level_ti


#: the Mann-only options (argparse dest -> flag), refused with --inflow kaimal
MANN_OPTIONS = {"mann_length_scale": "--mann-length-scale", "gamma": "--gamma",
                "alphaepsilon": "--alphaepsilon", "mann_nodes": "--mann-nodes"}


def _mann(args, speed, ti):
    """The `MannInflow` of the arguments: IEC 61400-1 Annex C defaults (``L = 0.7 Lambda_1``,
    ``Gamma = 3.9``), its level from ``sigma_u = ti U`` unless --alphaepsilon."""
    if args.gamma is not None and not args.gamma >= 0:
        raise ValueError(f"--gamma must be >= 0 (Mann's shear anisotropy; 0 is isotropic), got {args.gamma}")
    if args.mann_nodes is not None and args.mann_nodes < 4:
        raise ValueError(f"--mann-nodes must be at least 4, got {args.mann_nodes}")
    length = args.mann_length_scale or 0.7 * args.length_scale
    gamma = 3.9 if args.gamma is None else args.gamma
    level = {"alphaepsilon": args.alphaepsilon} if args.alphaepsilon else {"sigma_u": ti * speed}
    return lc.MannInflow(speed, length_scale=length, gamma=gamma, n_nodes=args.mann_nodes or 96, **level)


def _design(args, turbine, inflow):
    gate = (10.0, 80.0) if args.lidar == "pulsed" else args.gate
    d = dc.design_lac_scan(turbine, inflow, n_points=(args.beams,), distance=args.distance,
                           half_cone=(5.0, 40.0), gate_length=gate, lidar=args.lidar)
    print(f"design: half-cone {d.x[0]:.2f} deg"
          + (f", gate {d.x[1]:.1f} m" if args.lidar == "pulsed" else "")
          + f", scan radius {d.scan_radius:.1f} m ({d.scan_radius / turbine.radius:.2f} R), bandwidth "
          f"{d.bandwidth:.4f} Hz, {d.n_evaluations} evaluations")
    args.half_cone = float(d.x[0])
    if args.lidar == "pulsed":
        args.gate = float(d.x[1])
    return d


def run(args) -> int:
    if args.inflow != "mann":
        given = [flag for key, flag in MANN_OPTIONS.items() if getattr(args, key) is not None]
        if given:
            raise ValueError(f"{', '.join(given)}: only with --inflow mann")
    turbine, inflow, ti = _inputs(args)
    out = check_output_folder(args.out, files=FILES) if args.out else None
    design = _design(args, turbine, inflow) if args.design else None
    probe = PulsedProbe(30.0, args.gate, n_nodes=11) if args.lidar == "pulsed" else CWProbe(n_nodes=11)
    focus = lc.cone_points(args.distance, args.half_cone, args.beams,
                           azimuth_offset=45.0 if args.beams == 4 else 0.0)
    samples = lc.lidar_samples(focus, probe=probe)
    rotor = lc.rotor_disc(turbine.radius, spacing=min(args.grid, turbine.radius))
    f = np.linspace(args.fmax / args.nf, args.fmax, args.nf)
    sp = lc.lac_spectra(samples, rotor, inflow, f)
    f_b, k_b = (float(v) for v in lc.coherence_bandwidth(sp))
    cutoff = float(lc.filter_cutoff(sp))
    t_filter = float(lc.filter_delay(sp, cutoff)) if np.isfinite(cutoff) else float("nan")
    t_buffer = float(lc.buffer_time(args.distance, float(inflow.mean_speed), scan_time=args.scan_time,
                                    filter_delay=t_filter, prediction_time=args.prediction_time))
    summary = {"radius_m": turbine.radius, "mean_speed_m_s": float(inflow.mean_speed),
               "turbulence_intensity": ti, **_inflow_summary(inflow), "lidar": args.lidar,
               "beams": args.beams, "distance_m": args.distance, "half_cone_deg": args.half_cone,
               "gate_m": args.gate if args.lidar == "pulsed" else None,
               "bandwidth_hz": f_b, "bandwidth_rad_m": k_b, "cutoff_rad_s": cutoff, "filter_delay_s": t_filter,
               "buffer_time_s": t_buffer, "rotor_points": int(rotor.points.shape[0]),
               "lidar_nodes": int(samples.points.shape[0])}
    if design is not None:
        summary["design_evaluations"] = design.n_evaluations
    for key in ("bandwidth_hz", "bandwidth_rad_m", "cutoff_rad_s", "filter_delay_s", "buffer_time_s"):
        print(f"{key}: {summary[key]:.5g}")
    if out is not None:
        _write(out, sp, summary, focus, turbine.radius)
    return 0


def _inflow_summary(inflow):
    if isinstance(inflow, lc.MannInflow):
        return {"inflow": "mann", "alphaepsilon_m43_s2": float(inflow.alphaepsilon),
                "mann_length_scale_m": float(inflow.length_scale), "gamma": float(inflow.gamma),
                "mann_nodes": inflow.n_nodes}
    return {"inflow": "kaimal", "kaimal_length_scale_m": float(inflow.length_scale)}


def _write(out, sp, summary, focus, radius):
    out.mkdir(parents=True, exist_ok=True)
    table = np.column_stack([np.asarray(sp.frequency), np.asarray(sp.S_RR), np.asarray(sp.S_LL),
                             np.real(np.asarray(sp.S_RL)), np.imag(np.asarray(sp.S_RL)),
                             np.asarray(sp.coherence), np.asarray(sp.transfer)])
    np.savetxt(out / "lac_spectra.csv", table, delimiter=",", comments="",
               header="f_hz,S_RR,S_LL,S_RL_real,S_RL_imag,coherence,G_RL_abs")
    (out / "lac_summary.json").write_text(json.dumps(summary, indent=1))
    plt = import_optional("matplotlib.pyplot", "plot", "Drawing the lac pictures")
    fig, ax = plt.subplots(1, 2, figsize=(10, 4))
    f = np.asarray(sp.frequency)
    ax[0].semilogx(f, np.asarray(sp.coherence))
    ax[0].axhline(0.5, color="grey", lw=0.5)
    ax[0].axvline(summary["bandwidth_hz"], color="k", ls=":")
    ax[0].set(xlabel="f (Hz)", ylabel="coherence gamma^2")
    ax[1].semilogx(f, np.asarray(sp.transfer), label="|G_RL|")
    filt = 1 / np.sqrt(1 + (2 * np.pi * f / summary["cutoff_rad_s"]) ** 2)
    ax[1].semilogx(f, filt, "--", label="first-order filter")
    ax[1].set(xlabel="f (Hz)", ylabel="|G_RL|")
    ax[1].legend()
    fig.tight_layout()
    fig.savefig(out / "lac_coherence.png", dpi=100)
    plt.close(fig)
    fig, ax = plt.subplots(figsize=(5, 5))
    t = np.linspace(0, 2 * np.pi, 200)
    ax.plot(radius * np.cos(t), radius * np.sin(t), "k")
    fp = np.asarray(focus)
    ax.plot(fp[:, 1], fp[:, 2], "o", label=f"focus points at {summary['distance_m']:.0f} m")
    ax.set(aspect="equal", xlabel="y (m)", ylabel="z (m)", title="scan on the rotor disc")
    ax.legend()
    fig.savefig(out / "lac_disc.png", dpi=100)
    plt.close(fig)
