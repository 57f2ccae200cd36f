"""Synthetic lidar campaigns from known truth, in plain numpy, independent of the estimators
(`lidarjax.invert_joint`, `lidarjax.calibrate`): their own beam geometry, tilt and north
rotations written from the conventions in `lidarjax.frames`, and a CFD-like platform flow
whose distortion depends on the direction and on the inflow's shear exponent.

Used by tests/core/test_joint.py, tests/core/test_calibrate.py and
benchmarks/calibration.py (which puts the repository root on ``sys.path``).
"""

from __future__ import annotations

import numpy as np

#: Windcube V2: four beams at azimuths 0/90/180/270 (clockwise from the lidar's +y) at
#: 28 degrees from the vertical, and the vertical beam.
AZIMUTHS = np.array([0.0, 90.0, 180.0, 270.0])
CONE = 28.0


def rz(angle_deg):
    """Rotation about z, anticlockwise seen from above."""
    t = np.deg2rad(angle_deg)
    c, s = np.cos(t), np.sin(t)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def tilt(pitch_deg, roll_deg):
    """Body -> level lidar frame: R_x(pitch) @ R_y(roll)."""
    a, b = np.deg2rad(pitch_deg), np.deg2rad(roll_deg)
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    return rx @ ry


def body_beams(vertical: bool = True) -> np.ndarray:
    """Beam unit vectors ``(b, 3)`` in the body frame (x towards S1, y towards S0)."""
    c, a = np.deg2rad(CONE), np.deg2rad(AZIMUTHS)
    n = np.stack([np.sin(c) * np.sin(a), np.sin(c) * np.cos(a), np.full(4, np.cos(c))], -1)
    return np.vstack([n, [0.0, 0.0, 1.0]]) if vertical else n


def flow(d_lidar, heights, alpha):
    """Velocity per unit *local* free-stream speed at each beam point, lidar frame:
    ``(..., h, b, 3)`` for directions ``(..., h)`` (meteorological, lidar frame, degrees)
    and shear exponents broadcastable to ``(..., h)``. The platform speeds the flow up and
    tilts it by amounts that depend on the direction, the height, the beam and alpha."""
    d = np.deg2rad(np.asarray(d_lidar, np.float64))[..., None]  # (..., h, 1)
    a = np.asarray(alpha, np.float64)[..., None]
    z = np.asarray(heights, np.float64)[:, None]  # (h, 1)
    az = np.deg2rad(np.append(AZIMUTHS, 0.0))  # (b,)
    sp = (1.0 + 0.04 * np.cos(d - 0.5) * np.exp(-z / 80.0) * (1.0 + 3.0 * a)
          + 0.015 * np.cos(d - az) * np.exp(-z / 60.0) * (1.0 - a))
    w = 0.03 * np.sin(d + 0.3) * np.exp(-z / 120.0) * (1.0 - 2.0 * a) + 0.0 * az
    return np.stack([-np.sin(d) * sp, -np.cos(d) * sp, w], -1)


def table_runs(directions, heights, alpha, z_ref, *, epsilon=0.0, vertical=True):
    """What CFD runs of one inflow (shear exponent `alpha`, free stream given at `z_ref`)
    at the nominal installation (level, north offset `epsilon`) give, per unit reference
    speed: ``(response (s, h, b), beam_velocity (s, h, b, 3) north, beam_vectors (b, 3)
    north)``."""
    nb = body_beams(vertical)
    h = len(heights)
    d_lidar = np.broadcast_to((np.asarray(directions) - epsilon)[:, None], (len(directions), h))
    prof = (np.asarray(heights) / z_ref) ** alpha
    vel = flow(d_lidar, heights, alpha)[..., : nb.shape[0], :] * prof[None, :, None, None]
    response = np.einsum("shbk,bk->shb", vel, nb)
    north = rz(-epsilon)
    return response, np.einsum("ij,shbj->shbi", north, vel), nb @ north.T


def campaign(rng, n, heights, z_ref, *, alpha=(0.0, 0.3), epsilon=0.0,
             offsets=(0.0, 0.0, 0.0), sigma=0.1, vertical=True, speed=(4.0, 14.0)):
    """`n` records of LOS ``(n, h, b)`` (m/s, positive away from the lidar) with Gaussian
    noise `sigma`, from a lidar whose true north offset is ``epsilon + offsets[0]`` and tilt
    ``offsets[1:]`` (pitch, roll). Truth drawn uniformly: reference speed in `speed`,
    direction in [0, 360), shear exponent in `alpha` (a number: fixed).

    **Returns:** ``(los, truth)`` with truth a dict of ``speed_ref (n,)``, ``direction
    (n,)``, ``alpha (n,)``, ``speed (n, h)`` (local free stream)."""
    de, dp, dr = offsets
    nb = body_beams(vertical) @ tilt(dp, dr).T
    h = len(heights)
    u = rng.uniform(*speed, n)
    d = rng.uniform(0.0, 360.0, n)
    a = np.full(n, float(alpha)) if np.ndim(alpha) == 0 else rng.uniform(*alpha, n)
    local = u[:, None] * (np.asarray(heights) / z_ref)[None, :] ** a[:, None]  # (n, h)
    d_lidar = np.broadcast_to((d - (epsilon + de))[:, None], (n, h))
    vel = flow(d_lidar, heights, np.broadcast_to(a[:, None], (n, h)))[..., : nb.shape[0], :]
    los = local[..., None] * np.einsum("nhbk,bk->nhb", vel, nb)
    los = los + sigma * rng.standard_normal(los.shape)
    return los, {"speed_ref": u, "direction": d, "alpha": a, "speed": local}
