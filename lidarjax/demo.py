"""The built-in demonstration scene: lidars on a hemispherical 'platform' (seed 003, fig. 4).

A hemisphere of radius ``H`` stands in for the platform deck; the lidar sits just above its
surface, off the crown. Twelve CFD runs (inflow every 30 degrees) are simulated in one
compiled batch for Windcube V1, Windcube V2 and ZephIR, and compared with the point
measurement directly above the lidar: ``C_U = U / U_free`` and the direction error
``theta_free - theta`` against ``z / H``.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from .forward import simulate
from .mount import Mount
from .scan import windcube_v1, windcube_v2, zephir
from .scenes import heading, hemisphere

#: Demo geometry (metres, m/s, degrees).
RADIUS = 20.0
SPEED = 10.0
LOCATION = (4.0, 3.0, float(np.sqrt(RADIUS**2 - 4.0**2 - 3.0**2)) + 0.5)
DIRECTIONS = np.arange(0.0, 360.0, 30.0)
Z_OVER_H = np.array([1.1, 1.25, 1.5, 2.0, 3.0, 4.0, 5.0])
SCANS = {"windcube_v1": windcube_v1, "windcube_v2": windcube_v2, "zephir": zephir}


@dataclasses.dataclass(frozen=True)
class DemoResult:
    """Per scan, arrays shaped (sectors, heights): C_U and direction error (degrees)."""

    z_over_h: np.ndarray
    directions: np.ndarray
    c_u: dict[str, np.ndarray]
    dtheta: dict[str, np.ndarray]


def demo_heights() -> np.ndarray:
    """Measurement heights above the lidar (m) for the demo's z / H values."""
    return Z_OVER_H * RADIUS - LOCATION[2]


def run_demo_simulations(probe=None) -> tuple[DemoResult, dict]:
    """Simulate the three scans over the 12 directions (one compiled batch per scan)."""
    heights = jnp.asarray(demo_heights())
    mount = Mount(LOCATION, beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
    sims = {}
    for name, make in SCANS.items():
        scan = make()

        def one(direction, scan=scan):
            scene = hemisphere(RADIUS, SPEED, direction)
            return simulate(scene, scan, mount, heights, u_ref=SPEED * heading(direction),
                            probe=probe)

        sims[name] = jax.vmap(one)(jnp.asarray(DIRECTIONS))
    c_u, dth = {}, {}
    any_sim = sims["windcube_v1"]
    c_u["point"] = np.asarray(1.0 / (any_sim.cff_U / any_sim.cfp_U))
    dth["point"] = np.asarray(any_sim.cff_th - any_sim.cfp_th)
    for name, sim in sims.items():
        c_u[name] = np.asarray(1.0 / sim.cff_U)
        dth[name] = np.asarray(sim.cff_th)
    return DemoResult(Z_OVER_H, DIRECTIONS, c_u, dth), sims


def format_table(result: DemoResult) -> str:
    """Text table: per z/H, mean |C_U - 1| and max |dtheta| over the 12 directions."""
    cols = ["point", "windcube_v1", "windcube_v2", "zephir"]
    head = "  z/H " + "".join(f"{c:>15s}" for c in cols)
    lines = ["C_U = U/U_free: mean over 12 directions (max |C_U - 1| in brackets)", head]
    for k, zh in enumerate(result.z_over_h):
        row = f"{zh:5.2f} "
        for c in cols:
            v = result.c_u[c][:, k]
            row += f"{np.mean(v):6.3f} ({np.max(np.abs(v - 1)):.3f})".rjust(15)
        lines.append(row)
    lines += ["", "direction error theta_free - theta (deg): mean |error| (max |error|)", head]
    for k, zh in enumerate(result.z_over_h):
        row = f"{zh:5.2f} "
        for c in cols:
            v = np.abs(result.dtheta[c][:, k])
            row += f"{np.mean(v):6.2f} ({np.max(v):5.2f})".rjust(15)
        lines.append(row)
    return "\n".join(lines)
