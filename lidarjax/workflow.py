"""The seed UDF's workflow on top of `simulate`: settings.dat in, seed output files out.

`simulate_settings` runs every platform rotation (beta) of a `Settings` in one compiled
batch when the CFD runs share a grid (one trace, ``jax.vmap`` over the runs), and
`seed_columns` turns a `Simulation` into the seed's 21 output columns.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from .angles import horizontal_speed, seed_azimuth
from .batch import simulate_sectors, stack_fields
from .field import GridField
from .forward import Simulation, simulate
from .io.settings import Settings
from .mount import Mount
from .records import CorrectedRecords as CorrectedRecords
from .records import correct_records as correct_records
from .records import write_corrected_csv as write_corrected_csv

__all__ = ["seed_columns", "simulate_settings", "build_table", "correct_records",
           "write_corrected_csv", "CorrectedRecords", "SEED_U_REF"]

#: The free stream hard-coded in the seed UDF (its CFD inlet), CFD frame, m/s.
SEED_U_REF = (-15.0, 0.0, 0.0)


def seed_columns(sim: Simulation) -> dict[str, np.ndarray]:
    """The seed's 21 output columns for one `Simulation` (heights ``(h,)``).

    Speeds in m/s, ``Th_lidar`` / ``th_point`` in the seed's azimuth (flow heading clockwise
    from ``+x``; see `lidarjax.seed_azimuth`), factors as in `lidarjax.corrections`. Factors
    whose reference was not simulated are NaN.
    """
    h = np.asarray(sim.heights)
    nan = np.full(h.shape, np.nan)
    L = sim.lidar_velocity
    P = sim.point_velocity if sim.point_velocity is not None else jnp.full(L.shape, jnp.nan)
    cols = {
        "h": h,
        "U_mag_lidar": horizontal_speed(L), "U_lidar": L[:, 0], "V_lidar": L[:, 1],
        "W_lidar": L[:, 2], "Th_lidar": seed_azimuth(L),
        "U_mag_point": horizontal_speed(P), "U_point": P[:, 0], "V_point": P[:, 1],
        "W_point": P[:, 2], "th_point": seed_azimuth(P),
    }
    for name in ("cff_u", "cff_v", "cff_w", "cff_U", "cff_th",
                 "cfp_u", "cfp_v", "cfp_w", "cfp_U", "cfp_th"):
        value = getattr(sim, name)
        cols[name] = nan if value is None else value
    return {k: np.asarray(v, dtype=np.float64) for k, v in cols.items()}


def settings_mounts(settings: Settings, betas: Sequence[float], *, pitch: float = 0.0,
                    roll: float = 0.0) -> list[Mount]:
    """The `Mount` of each platform rotation: the settings' location row for that beta and
    its gamma, psi and epsilon, with the installation's `pitch` and `roll` (degrees)."""
    return [Mount(settings.location(b), beta=b, gamma=settings.gamma, psi=settings.psi,
                  epsilon=settings.epsilon, pitch=pitch, roll=roll) for b in betas]


def simulate_settings(
    settings: Settings,
    betas: Sequence[float],
    field_for_beta: Callable[[float], GridField],
    scan,
    *,
    u_ref=SEED_U_REF,
    probe=None,
    pitch: float = 0.0,
    roll: float = 0.0,
) -> dict[float, Simulation]:
    """Simulate the lidar of `settings` for each platform rotation in `betas`.

    **Arguments:**

    - `settings`: a `lidarjax.io.Settings` (heights ``j * height / nh``, gamma, psi,
      epsilon and one location per beta).
    - `betas`: platform rotations (degrees) to run; each needs a location row.
    - `field_for_beta`: loads the CFD run of one beta (e.g. ``lidarjax.io.load_field``).
    - `scan`: the `lidarjax.Scan`.
    - `u_ref`: free-stream vector in the CFD frame (m/s); default the seed UDF's.
    - `probe`: probe volume (default point).
    - `pitch`, `roll`: the installation's tilt in degrees (`lidarjax.Mount`), default level.

    **Returns:** ``{beta: Simulation}``. Runs on one grid are simulated in one compiled,
    vmapped batch; otherwise one call per run (one compilation per distinct grid shape).
    """
    betas = [float(b) for b in betas]
    mounts = settings_mounts(settings, betas, pitch=pitch, roll=roll)
    heights = jnp.asarray(settings.heights())
    fields = [field_for_beta(b) for b in betas]
    try:
        stacked = stack_fields(fields) if len(fields) > 1 else None
    except ValueError:  # runs on different grids: one call (and compilation) per grid
        stacked = None
    if stacked is None:
        return {b: simulate(f, scan, m, heights, u_ref=u_ref, probe=probe)
                for b, f, m in zip(betas, fields, mounts, strict=True)}
    batch = simulate_sectors(stacked, scan, mounts, heights, u_refs=u_ref, probe=probe)
    return {b: jax.tree_util.tree_map(lambda a, i=i: a[i], batch) for i, b in enumerate(betas)}


def build_table(
    settings: Settings,
    betas: Sequence[float],
    field_for_beta: Callable[[float], GridField],
    scan,
    *,
    u_ref=SEED_U_REF,
    probe=None,
    pitch: float = 0.0,
    roll: float = 0.0,
):
    """A `lidarjax.ResponseTable` from the CFD runs of a seed settings file.

    Each platform rotation ``beta`` is one inflow direction; the table's directions are the
    free streams' meteorological directions in the north frame. Returns ``(table, sims)``.
    """
    from .response import ResponseTable

    sims = simulate_settings(settings, betas, field_for_beta, scan, u_ref=u_ref, probe=probe,
                             pitch=pitch, roll=roll)
    table = ResponseTable.from_simulations(
        list(sims.values()), mount=settings_mounts(settings, list(sims), pitch=pitch, roll=roll))
    return table, sims
