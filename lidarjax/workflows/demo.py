"""`lidarjax demo`: the whole job on a built-in platform scene, with no input files.

The platform is a hemisphere of radius ``H = 20 m`` in potential flow (`scenes.hemisphere`),
the CFD free stream is the seed UDF's ``(-15, 0, 0)`` m/s with ``psi = 180``, and the lidar
sits 0.5 m above the deck, off the crown. As in the seed, the platform is rotated by
``beta = 0, 30, ..., 330`` (12 CFD runs, one per inflow direction), so the lidar's location
in the CFD frame turns with it. The demo

1. writes the seed's ``settings.dat`` and simulates Windcube V1 and V2 (pulsed probe) and
   ZephIR (CW probe) for the 12 runs, each scan in one compiled batch;
2. writes the seed output files (``windcube simulation <beta> degrees.dat``, Windcube V1)
   and self-describing CSV tables;
3. builds the Windcube V2 response table from the 12 runs (``table.npz``);
4. makes a month of synthetic 10-minute records at random speeds and directions (not the
   tabulated ones; LOS noise 0.1 m/s), writes them as a Windcube ``.sta`` file, and corrects
   them through the same path as ``lidarjax correct`` (``synthetic_corrected.csv``);
5. simulates one day of Windcube V2 10-minute records (pulsed probe, 1 s per LOS) in a
   generated Mann box (lidarjax's numpy FFT generator, no extra needed) advected over the
   platform flow, and writes the simulated ``.sta``, the statistics and the lidar-against-
   point TI figure (``series/``);
6. draws the figures (with matplotlib): C_U and direction error against z/H (seed 003,
   figure 4), LOS against scan azimuth with the fitted sine (figure 2), correction roses,
   and a gradient map of which part of the flow drives the lidar's speed error.
"""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .._util import nan_max, nan_mean
from ..batch import simulate_rotations
from ..field import GridField
from ..frames import rotation_z
from ..io import Settings, save_table, write_seed_output, write_settings, write_sta, write_table_csv
from ..io.seed_output import SEED_UNITS
from ..mount import Mount
from ..plots import (
    plot_budget,
    plot_los_fit,
    plot_profiles,
    plot_roses,
    plot_sensitivity,
    plot_sensitivity_profiles,
    sensitivity_map,
)
from ..probe import CWProbe, PulsedProbe
from ..response import ResponseTable
from ..roses import correction_rose
from ..scan import reconstruct, windcube_v1, windcube_v2, zephir
from ..scenes import FrozenTurbulence, hemisphere
from ..sensitivity import OUTPUTS, budget_columns, uncertainty
from ..series import RECORD_LENGTH, simulate_statistics
from ..turbulence import TurbulenceBox, fft_mann_box
from .records import correct_records, write_corrected_csv
from .seed_tables import seed_columns, simulate_settings
from .series_report import write_series_report

__all__ = ["run_demo"]

#: Demo geometry (metres, m/s, degrees).
RADIUS = 20.0
SPEED = 15.0
U_REF = (-SPEED, 0.0, 0.0)  # the seed UDF's CFD free stream
PSI = 180.0
DECK = (4.0, 3.0, float(np.sqrt(RADIUS**2 - 4.0**2 - 3.0**2)) + 0.5)  # lidar, beta = 0 (CFD)
BETAS = np.arange(0.0, 360.0, 30.0)
HEIGHT, NH = 80.0, 16  # settings.dat: heights j * HEIGHT / NH
SCANS = {"windcube_v1": (windcube_v1, PulsedProbe), "windcube_v2": (windcube_v2, PulsedProbe),
         "zephir": (zephir, CWProbe)}
N_RECORDS = 30 * 144  # a month of 10-minute records
LOS_NOISE = 0.1  # m/s


@dataclasses.dataclass(frozen=True)
class DemoResult:
    """Per scan, arrays shaped (sectors, heights): C_U and direction error (degrees)."""

    z_over_h: np.ndarray
    directions: np.ndarray
    c_u: dict[str, np.ndarray]
    dtheta: dict[str, np.ndarray]


def scene():
    """The CFD run: the hemisphere 'platform' in the seed's free stream (from +x)."""
    return hemisphere(RADIUS, SPEED, 90.0)


def heights() -> np.ndarray:
    """The seed's heights above the lidar, m: ``j * HEIGHT / NH``."""
    return np.arange(1, NH + 1) * HEIGHT / NH


@jax.jit
def location(beta):
    """The lidar in the CFD frame when the platform is rotated by `beta` degrees (the deck
    position turns by ``beta``: ``R(beta - psi) R(psi) DECK``); works on traced `beta`. One
    compiled program (eagerly, its rotations would compile each operation on their own)."""
    return rotation_z(beta - PSI) @ rotation_z(PSI) @ jnp.asarray(DECK)


def mount_for(beta) -> Mount:
    """The seed mount for platform rotation `beta` (gamma = epsilon = 0, psi = 180)."""
    return Mount(location(beta), beta=beta, gamma=0.0, psi=PSI, epsilon=0.0)


def settings():
    """The demo's seed settings.dat contents."""

    return Settings(zone=2, verbose=1, height=HEIGHT, nh=NH, gamma=0.0, beta=0.0, psi=PSI,
                    epsilon=0.0, betas=BETAS,
                    locations=np.stack([np.asarray(location(b)) for b in BETAS]))


def run_demo_simulations() -> tuple[DemoResult, dict]:
    """The three scans over the 12 platform rotations, one compiled batch per scan."""

    st = settings()
    sims = {}
    for name, (make, probe) in SCANS.items():
        batch = simulate_settings(st, BETAS, lambda b: scene(), make(), u_ref=U_REF,
                                  probe=probe())
        sims[name] = batch
    stacked = {k: jax.tree_util.tree_map(lambda *a: np.stack(a), *v.values())
               for k, v in sims.items()}
    v1 = stacked["windcube_v1"]
    c_u = {"point": np.asarray(v1.cfp_U / v1.cff_U)}
    dth = {"point": np.asarray(v1.cff_th - v1.cfp_th)}
    for name, sim in stacked.items():
        c_u[name] = np.asarray(1.0 / sim.cff_U)
        dth[name] = np.asarray(sim.cff_th)
    z_over_h = (DECK[2] + heights()) / RADIUS
    return DemoResult(z_over_h, BETAS, c_u, dth), sims


def format_table(result: DemoResult, rows=None) -> str:
    """Text table: per z/H, mean C_U (max |C_U - 1|) and mean (max) |dtheta| over directions
    (``nan`` where no direction gave a value: the point is outside the field or in a solid)."""
    cols = ["point", "windcube_v1", "windcube_v2", "zephir"]
    head = "  z/H " + "".join(f"{c:>15s}" for c in cols)
    rows = range(len(result.z_over_h)) if rows is None else rows
    lines = ["C_U = U / U_free: mean over 12 directions (max |C_U - 1|)", head]
    for k in rows:
        row = f"{result.z_over_h[k]:5.2f} "
        for c in cols:
            v = result.c_u[c][:, k]
            row += f"{nan_mean(v):6.3f} ({nan_max(np.abs(v - 1)):.3f})".rjust(15)
        lines.append(row)
    lines += ["", "direction error theta_free - theta (deg): mean |error| (max |error|)", head]
    for k in rows:
        row = f"{result.z_over_h[k]:5.2f} "
        for c in cols:
            v = np.abs(result.dtheta[c][:, k])
            row += f"{nan_mean(v):6.2f} ({nan_max(v):5.2f})".rjust(15)
        lines.append(row)
    return "\n".join(lines)


@jax.jit
def _reconstruct_v2(los):
    """The Windcube V2's reported wind of every record ``(n, h, b)``: one compiled program
    (an eager vmap compiles each of its operations on its own)."""
    return jax.vmap(lambda x: reconstruct(windcube_v2(), x))(los)


def synthetic_records(n: int = N_RECORDS, seed: int = 0):
    """Truth and Windcube V2 output for `n` 10-minute records at random speeds (Weibull,
    A = 10 m/s, k = 2) and directions (uniform), with LOS noise `LOS_NOISE`.

    The platform rotation of each record is its own (not a tabulated one), simulated with
    the pulsed probe. Returns ``(time, speed, direction, los, reported_velocity)``."""
    rng = np.random.default_rng(seed)
    speed = 10.0 * rng.weibull(2.0, n) + 0.5
    betas = rng.uniform(0.0, 360.0, n)
    mounts = jax.vmap(mount_for)(jnp.asarray(betas))
    sims = simulate_rotations(scene(), windcube_v2(), mounts, heights(), u_refs=jnp.asarray(U_REF),
                            probe=PulsedProbe(), point_reference=False)
    scale = speed / SPEED
    los = np.asarray(sims.los) * scale[:, None, None]
    direction = np.asarray(sims.free_direction)
    los = los + rng.normal(scale=LOS_NOISE, size=los.shape)
    reported = np.asarray(_reconstruct_v2(los))
    t0 = np.datetime64("2025-01-01T00:10")
    times = t0 + np.arange(n) * np.timedelta64(10, "m")
    return times, speed, direction, los, reported


def run_demo(out: Path, *, plots: bool = True, log=print) -> dict:
    """Run everything and write it under `out`; returns a summary dict."""

    t0 = time.perf_counter()
    out = Path(out)
    (out / "seed").mkdir(parents=True, exist_ok=True)
    summary: dict = {}

    write_settings(out / "seed" / "settings.dat", settings())
    result, sims = run_demo_simulations()
    for beta, sim in sims["windcube_v1"].items():
        cols = seed_columns(sim)
        write_seed_output(out / "seed", beta, cols, verbose=1)
        write_table_csv(out / "seed" / f"simulation_{beta:g}.csv", cols, SEED_UNITS,
                        {"scan": "windcube_v1", "probe": "PulsedProbe()", "beta_deg": beta})
    log(f"[{time.perf_counter() - t0:5.1f} s] simulated V1, V2, ZephIR x 12 platform rotations; "
        f"seed files in {out / 'seed'}")

    v2 = list(sims["windcube_v2"].values())
    table = ResponseTable.from_simulations(v2, mount=[mount_for(b) for b in BETAS],
                                           scan=windcube_v2(), probe=PulsedProbe())
    save_table(out / "table.npz", table, {"scan": "windcube_v2", "probe": "PulsedProbe()",
                                          "scene": "hemisphere R=20 m, demo"})

    times, speed, direction, los, reported = synthetic_records()
    rep_speed = np.hypot(reported[..., 0], reported[..., 1])
    rep_dir = np.mod(np.degrees(np.arctan2(-reported[..., 0], -reported[..., 1])), 360.0)
    write_sta(out / "synthetic.sta", times, heights(), rep_speed, rep_dir, w=reported[..., 2],
              scan_angle=28.0, direction_offset=0.0)
    corrected = correct_records(table, out / "synthetic.sta", noise=LOS_NOISE / np.sqrt(2.0))
    write_corrected_csv(out / "synthetic_corrected.csv", corrected,
                        {"records": "synthetic.sta", "table": "table.npz"})
    truth = np.broadcast_to(speed[:, None], rep_speed.shape)
    err_raw = rep_speed - truth
    err_cor = corrected.speed - truth
    dir_raw = np.abs((rep_dir - direction[:, None] + 180) % 360 - 180)
    dir_cor = np.abs((corrected.direction - direction[:, None] + 180) % 360 - 180)
    summary["records"] = {
        "n_records": int(len(times)), "heights": int(NH),
        "converged_fraction": float(np.mean(corrected.converged)),
        "speed_bias_uncorrected": float(np.nanmean(err_raw)),
        "speed_bias_corrected": float(np.nanmean(err_cor)),
        "speed_rms_uncorrected": float(np.sqrt(np.nanmean(err_raw**2))),
        "speed_rms_corrected": float(np.sqrt(np.nanmean(err_cor**2))),
        "direction_mae_uncorrected": float(np.nanmean(dir_raw)),
        "direction_mae_corrected": float(np.nanmean(dir_cor)),
    }
    log(f"[{time.perf_counter() - t0:5.1f} s] corrected {len(times)} synthetic records x {NH} "
        f"heights from {out / 'synthetic.sta'} -> {out / 'synthetic_corrected.csv'}")

    summary["sensitivity"] = run_sensitivity(out / "sensitivity", plots=plots)
    log(f"[{time.perf_counter() - t0:5.1f} s] installation uncertainty budget (V2, 12 platform "
        f"rotations, one batch): u(U) <= {summary['sensitivity']['lidar_speed']:.3g} m/s, "
        f"u(direction) <= {summary['sensitivity']['lidar_direction']:.3g} deg, u(C_U) <= "
        f"{summary['sensitivity']['cff_U']:.3g} -> {out / 'sensitivity'}")
    summary["series"] = series_day(out / "series", plots=plots)
    log(f"[{time.perf_counter() - t0:5.1f} s] simulated one day of Windcube V2 10-minute records "
        f"in a generated Mann box over the platform flow -> {out / 'series'}")

    if plots:
        try:
            summary["plots"] = [str(p) for p in _plots(out / "plots", result, sims, table)]
            log(f"[{time.perf_counter() - t0:5.1f} s] figures in {out / 'plots'}")
        except ImportError as err:
            log(f"(no figures: {err})")
    summary["table"] = format_table(result, rows=range(0, NH, 2))
    summary["seconds"] = time.perf_counter() - t0
    return summary


def _plots(folder: Path, result: DemoResult, sims: dict, table):
    paths = [plot_profiles(result.z_over_h, result.c_u, result.dtheta, folder / "profiles.png",
                           title="hemisphere platform (H = 20 m), 12 directions, probe volumes")]
    zsim = sims["zephir"][60.0]
    k = 5
    scan = zephir()
    fit = reconstruct(scan, zsim.los[k])
    paths.append(plot_los_fit(np.asarray(scan.beam_azimuths()), zsim.los[k], fit, 30.0,
                              folder / "los_fit.png",
                              title=f"ZephIR at h = {float(zsim.heights[k]):g} m, beta = 60"))
    rose = correction_rose(table, resolution=1.0)
    cols = [1, 5, 11]
    paths.append(plot_roses(np.asarray(rose.directions), np.asarray(rose.speed_ratio)[:, cols],
                            np.asarray(rose.direction_addend)[:, cols],
                            [f"h = {h:g} m" for h in heights()[cols]], folder / "roses.png",
                            title="Windcube V2 corrections to the free stream (1 degree)"))
    x = np.arange(-40.0, 48.0, 2.0)
    z = np.arange(0.0, 64.0, 2.0)
    grid = GridField.from_function(scene().sample, x, x, z)
    mount = mount_for(0.0)
    sens = sensitivity_map(grid, windcube_v2(), mount, 20.0, u_ref=U_REF, probe=PulsedProbe())
    paths.append(plot_sensitivity(grid, sens, np.asarray(location(0.0)), 20.0,
                                  folder / "sensitivity.png",
                                  title="d(U_V2 - U_free)/dV at h = 20 m, beta = 0, pulsed probe"))
    return paths


#: Installation standard uncertainties of the demo's budget (degrees, metres).
DEMO_STD = {"epsilon": 0.5, "gamma": 0.5, "pitch": 0.2, "roll": 0.2, "location": 0.05}


def run_sensitivity(out: Path, *, plots: bool = True) -> dict:
    """The Windcube V2's installation uncertainty budget for the 12 platform rotations in one
    compiled batch (`lidarjax.uncertainty`, pulsed probe, `DEMO_STD`): writes one CSV per
    output and, with matplotlib, budget bars and sensitivity profiles. Returns the largest
    standard uncertainty of each output over rotations and heights."""

    outputs = ("lidar_speed", "lidar_direction", "cff_U", "cff_th")
    mounts = jax.vmap(mount_for)(jnp.asarray(BETAS))
    budget = uncertainty(scene(), windcube_v2(), mounts, heights(), std=DEMO_STD, u_ref=U_REF,
                         probe=PulsedProbe(), outputs=outputs)
    budget = jax.tree_util.tree_map(np.asarray, budget)
    z_over_h = (DECK[2] + heights()) / RADIUS
    meta = {"scene": "hemisphere R=20 m, demo", "scan": "windcube_v2", "probe": "PulsedProbe()",
            "std": ";".join(f"{k}={v}" for k, v in DEMO_STD.items())}
    out.mkdir(parents=True, exist_ok=True)
    for o in outputs:
        cols, units = budget_columns(budget, o, BETAS, z_over_h)
        write_table_csv(out / f"budget_{o}.csv", cols, units, meta)
    if plots:
        try:
            k = int(np.nanargmax(np.nanmax(budget.std["lidar_speed"], axis=-1)))
            rows = np.arange(0, NH, 3)
            plot_budget(z_over_h[rows], budget.inputs,
                        {o: budget.contribution[o][k][rows] for o in outputs},
                        {o: budget.std[o][k][rows] for o in outputs},
                        {o: OUTPUTS[o] for o in outputs}, out / "budget.png",
                        title=f"Windcube V2 installation budget, beta = {BETAS[k]:g} deg")
            plot_sensitivity_profiles(
                z_over_h, budget.inputs, {o: budget.jacobian[o] for o in outputs},
                {(o, n): f"{OUTPUTS[o]} per {u}" for o in outputs
                 for n, u in zip(budget.inputs, budget.input_units, strict=True)},
                out / "sensitivity_profiles.png",
                title="Windcube V2 sensitivities, hemisphere platform, 12 rotations")
        except ImportError:
            pass
    return {o: float(np.nanmax(budget.std[o])) for o in outputs}
#: One simulated day: heights above the lidar (m), box nodes and spacing (m), target TI.
SERIES_HEIGHTS = (20.0, 40.0, 60.0, 80.0)
SERIES_BOX = ((256, 32, 32), (4.0, 4.0, 4.0))
SERIES_TI = 0.08


def series_day(out: Path, *, plots: bool = True, seed: int = 0) -> dict:
    """One simulated day (144 records) of a Windcube V2 on the platform (beta = 0) in a
    generated periodic Mann box (L = 30 m, Gamma = 3.9, sigma_u = 8 % of the free stream)
    advected over the hemisphere's potential flow; returns mean TIs per height."""

    (shape, spacing) = SERIES_BOX
    vel = fft_mann_box(shape, spacing, length_scale=30.0, gamma=3.9, sigma_u=SERIES_TI * SPEED,
                       seed=seed)
    mean = scene()
    box = TurbulenceBox(jnp.asarray(vel, mean.dtype), jnp.asarray(spacing, mean.dtype),
                        periodic=(True, True))
    anchor = np.asarray(location(0.0)) - np.asarray(mean.origin)
    field = FrozenTurbulence(mean, box, SPEED, 90.0, anchor=anchor)  # the free stream from +x
    starts = np.arange(144) * RECORD_LENGTH
    scan = windcube_v2()
    stats = simulate_statistics(field, scan, mount_for(0.0), np.asarray(SERIES_HEIGHTS), starts,
                                probe=PulsedProbe(), chunk=144)
    res = write_series_report(out, stats, SERIES_HEIGHTS, starts,
                              start_datetime=np.datetime64("2024-01-01T00:00"), scan=scan,
                              metadata={"scene": "hemisphere R=20 m, demo", "box": str(SERIES_BOX)},
                              plots=plots, label="Windcube V2")
    return {"heights": list(SERIES_HEIGHTS),
            "ti_lidar": np.nanmean(stats.ti, axis=0).tolist(),
            "ti_cup": np.nanmean(stats.cup_ti, axis=0).tolist(),
            "availability": np.nanmean(stats.availability, axis=0).tolist(),
            "files": [str(v) for k, v in res.items() if k != "note" and v]}
