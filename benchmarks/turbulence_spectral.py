"""Lidar against point turbulence intensity in Mann turbulence: the simulator against the
spectral model (Sathe et al. 2011), with the ensemble's statistical uncertainty.

What it runs: an ensemble of periodic Mann boxes (L = 33.6 m, Gamma = 3.9, the IEC values;
512 x 64 x 64 nodes at 4 m: 2048 x 256 x 256 m) synthesised with the exact discrete spectrum
(`lidarjax.turbulence.synthesize_box`), advected at 10 m/s over a uniform 10 m/s mean wind
(`lidarjax.scenes.FrozenTurbulence`). In every box a Windcube V2 (pulsed probe, full scale)
and a ZephIR (50 LOS, CW probe, full scale) measure at 100 m for one box period (204.8 s,
the record), from two lateral positions half a box apart, every beam of a scan at the same
instant; a point sensor (sonic) sits at 100 m above each lidar. Per record: the variance of
the reconstructed along-wind component ``u`` (lidar) and of ``u`` (point). Two wind
directions relative to the lidar: 270 (along beam S1-S3) and 225 (between beams).

Model: `lidarjax.spectral.lidar_variance` on the same box wavenumbers and record, with
(a) ``probe_model="nodes", interpolation="trilinear"``: what the simulator computes, and
(b) ``probe_model="weight"``: the ideal instruments (untruncated weightings, continuous field
of the box's modes), Sathe et al.'s quantity; (c) ``probe_model="truncated"``: the weightings
as the simulator integrates them (the CW Lorentzian cut at the lidar, 4 % of its weight at
100 m). Probe nodes are those `simulate` chooses for the box (`lidarjax.probe_for_field`).

Reported: ensemble means and standard errors of the lidar and point variances and of the
ratio (ratio of the ensemble means, standard error by the delta method over records), the
model values and the z-scores ``(ensemble - model) / standard error``.

Run ``python benchmarks/turbulence_spectral.py [--quick]`` (quick: 4 boxes, 256 x 32 x 32 at
8 m); writes ``benchmarks/results/turbulence_spectral.json``, ``.md`` and ``.png``.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)

import equinox as eqx  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from _common import machine  # noqa: E402

import lidarjax as lj  # noqa: E402
from lidarjax import spectral  # noqa: E402
from lidarjax.scenes import FrozenTurbulence  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
L, GAMMA, U, H = 33.6, 3.9, 10.0, 100.0
INSTRUMENTS = {
    "Windcube V2 (pulsed)": (lj.windcube_v2(), lj.PulsedProbe()),
    "ZephIR (CW, 50 LOS)": (lj.zephir(), lj.CWProbe()),
}


@eqx.filter_jit
def _records(box, scan, probe, direction, y0, n_times):
    """Reconstructed and point velocity series (n_times, 3), lidar frame = CFD frame."""
    d = jnp.deg2rad(direction)
    ey = jnp.stack([jnp.cos(d), -jnp.sin(d), 0.0 * d])  # the box's lateral axis (left of the wind)
    dy, dz = box.spacing[1], box.spacing[2]
    # the point sensors (H above each lidar) sit on node columns of the box: node (ny/2, H/dz)
    anchor = -0.5 * dy * (box.shape[1] % 2 == 0) * ey + jnp.stack([0.0, 0.0, jnp.mod(H, dz)])
    f = FrozenTurbulence(lj.scenes.uniform(U, direction), box, U, direction, anchor=anchor)
    period = box.length / U
    ts = jnp.arange(n_times) * (period / n_times)
    mount = lj.Mount(y0 * ey)

    def one(t):
        sim = lj.simulate(f.advanced(t), scan, mount, jnp.asarray([H]), probe=probe)
        return sim.lidar_velocity[0], sim.point_velocity[0], sim.flags[0]

    return jax.vmap(one)(ts)


def along_wind(v, direction):
    d = np.deg2rad(direction)
    return v[:, 0] * -np.sin(d) + v[:, 1] * -np.cos(d)


def ratio_stats(lid, pnt):
    """Ratio of means and its standard error (delta method over records)."""
    lid, pnt = np.asarray(lid), np.asarray(pnt)
    n = lid.size
    r = lid.mean() / pnt.mean()
    resid = (lid - r * pnt) / pnt.mean()
    return float(r), float(resid.std(ddof=1) / np.sqrt(n))


def main(quick: bool) -> None:
    if quick:
        shape, spacing, n_boxes = (256, 32, 32), (8.0, 8.0, 8.0), 4
    else:
        shape, spacing, n_boxes = (512, 64, 64), (4.0, 4.0, 4.0), 16
    directions = (270.0, 225.0)
    n_times = 4 * shape[0]
    record = shape[0] * spacing[0] / U
    y_positions = (0.0, shape[1] * spacing[1] / 2)
    samples = {(name, d): ([], []) for name in INSTRUMENTS for d in directions}
    refined = {}
    t0 = time.perf_counter()
    for seed in range(n_boxes):
        box = lj.synthesize_box(shape, spacing, 1.0, L, GAMMA, seed=seed)
        for name, (scan, probe) in INSTRUMENTS.items():
            # the nodes simulate chooses for the box's resolution (outside the jit: host numbers)
            probe = refined[name] = lj.probe_for_field(
                FrozenTurbulence(lj.scenes.uniform(U, 270.0), box, U, 270.0), scan, [H], probe)
            for d in directions:
                for y0 in y_positions:
                    lv, pv, flags = (np.asarray(a) for a in _records(box, scan, probe, d, y0, n_times))
                    bad = int(lj.Flag.BEAM_OUTSIDE | lj.Flag.POINT_OUTSIDE | lj.Flag.PROBE_TRUNCATED)
                    assert not np.any(flags & bad), np.unique(flags)
                    samples[(name, d)][0].append(np.var(along_wind(lv, d)))
                    samples[(name, d)][1].append(np.var(along_wind(pv, d)))
        print(f"box {seed + 1}/{n_boxes} done, {time.perf_counter() - t0:.0f} s", flush=True)
    t_sim = time.perf_counter() - t0
    rows = []
    t1 = time.perf_counter()
    for (name, d), (lid, pnt) in samples.items():
        scan, probe = INSTRUMENTS[name][0], refined[name]
        common = dict(box_shape=shape, box_spacing=spacing, speed=U, record_length=record, direction=d)
        like = spectral.lidar_variance(scan, probe, H, L, GAMMA, probe_model="nodes",
                                       interpolation="trilinear", **common)
        ideal = spectral.lidar_variance(scan, probe, H, L, GAMMA, probe_model="weight", **common)
        cut = spectral.lidar_variance(scan, probe, H, L, GAMMA, probe_model="truncated", **common)
        lid, pnt = np.asarray(lid), np.asarray(pnt)
        r, r_err = ratio_stats(lid, pnt)
        n = lid.size
        row = dict(
            instrument=name, direction=d, records=n,
            lidar_var=float(lid.mean()), lidar_var_err=float(lid.std(ddof=1) / np.sqrt(n)),
            point_var=float(pnt.mean()), point_var_err=float(pnt.std(ddof=1) / np.sqrt(n)),
            ratio=r, ratio_err=r_err,
            model_lidar_var=like.lidar, model_point_var=like.point, model_ratio=like.ratio,
            ideal_ratio=ideal.ratio, ideal_ti_ratio=ideal.ti_ratio, cut_ratio=cut.ratio,
            probe_nodes=probe.n_nodes,
        )
        row["z_ideal"] = (r - ideal.ratio) / r_err
        row["z_lidar"] = (row["lidar_var"] - like.lidar) / row["lidar_var_err"]
        row["z_point"] = (row["point_var"] - like.point) / row["point_var_err"]
        row["z_ratio"] = (r - like.ratio) / r_err
        rows.append(row)
        print(json.dumps(row), flush=True)
    t_model = time.perf_counter() - t1
    out = dict(
        description=__doc__.split("\n\n")[0],
        setup=dict(L=L, Gamma=GAMMA, U=U, height=H, box_shape=shape, box_spacing=spacing,
                   boxes=n_boxes, lateral_positions=len(y_positions), record_s=record,
                   samples_per_record=n_times, quick=quick),
        seconds=dict(simulation=t_sim, model=t_model),
        machine=machine(),
        rows=rows,
    )
    RESULTS.mkdir(exist_ok=True)
    name = "turbulence_spectral" + ("_quick" if quick else "")
    (RESULTS / f"{name}.json").write_text(json.dumps(out, indent=2))
    lines = [
        "| instrument | nodes | wind dir. | records | lidar/point variance (sim.) | model (as simulated) "
        "| z | ideal instrument model | z (ideal) | weighting as cut | TI ratio (ideal) |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['instrument']} | {r['probe_nodes']} | {r['direction']:.0f} | {r['records']} | "
            f"{r['ratio']:.3f} +- {r['ratio_err']:.3f} | {r['model_ratio']:.3f} | {r['z_ratio']:+.1f} | "
            f"{r['ideal_ratio']:.3f} | {r['z_ideal']:+.1f} | {r['cut_ratio']:.3f} | "
            f"{r['ideal_ti_ratio']:.3f} |"
        )
    (RESULTS / f"{name}.md").write_text("\n".join(lines) + "\n")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:  # pragma: no cover
        return
    fig, ax = plt.subplots(figsize=(7, 3.6))
    x = np.arange(len(rows))
    ax.errorbar(x - 0.1, [r["ratio"] for r in rows], yerr=[2 * r["ratio_err"] for r in rows], fmt="o",
                label="simulated ensemble (+- 2 s.e.)")
    ax.plot(x + 0.1, [r["model_ratio"] for r in rows], "s", label="spectral model, as simulated")
    ax.plot(x + 0.1, [r["ideal_ratio"] for r in rows], "x", label="spectral model, ideal instrument")
    ax.axhline(1.0, color="0.7", lw=0.8)
    ax.set_xticks(x, [f"{r['instrument'].split(' (')[0]}\n{r['direction']:.0f} deg" for r in rows])
    ax.set_ylabel("lidar / point variance of u")
    ax.set_title(f"Mann turbulence L={L} m, Gamma={GAMMA}, {H:.0f} m, {n_boxes} boxes")
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(RESULTS / f"{name}.png", dpi=120)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="4 small boxes")
    main(parser.parse_args().quick)
