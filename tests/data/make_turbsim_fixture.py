"""Recipe of tests/data/turbsim_small.bts: a TurbSim full-field file written by an independent
writer (openfast_io's `TurbSimFile.write`, the OpenFAST project's Python reader/writer), from
the closed-form field `turbsim_fixture_velocity` below. Run from the repository root:

    pip install openfast-io && python3 tests/data/make_turbsim_fixture.py
"""

from pathlib import Path

import numpy as np

NT, NY, NZ = 12, 5, 4
DT, DY, DZ, Z_BOTTOM, U_HUB, Z_HUB = 0.25, 3.0, 2.5, 20.0, 9.5, 23.75


def turbsim_fixture_velocity() -> np.ndarray:
    """``(nt, ny, nz, 3)`` full velocities (m/s) of the fixture."""
    t = np.arange(NT)[:, None, None] * DT
    y = (np.arange(NY) - (NY - 1) / 2)[None, :, None] * DY
    z = (Z_BOTTOM + np.arange(NZ) * DZ)[None, None, :]
    u = U_HUB + 1.5 * np.sin(2 * np.pi * t / (NT * DT)) + 0.02 * y + 0.05 * (z - Z_HUB)
    v = -0.8 * np.cos(2 * np.pi * 2 * t / (NT * DT)) + 0.01 * y * z / 10
    w = 0.3 * np.sin(0.7 * y + 0.3 * z) + 0 * t
    return np.stack(np.broadcast_arrays(u, v, w), axis=-1)


if __name__ == "__main__":
    from openfast_io.turbsim_file import TurbSimFile

    ts = TurbSimFile()
    vel = turbsim_fixture_velocity()
    ts["u"] = np.moveaxis(vel, -1, 0)  # (3, nt, ny, nz)
    ts["t"] = np.arange(NT) * DT
    ts["y"] = (np.arange(NY) - (NY - 1) / 2) * DY
    ts["z"] = Z_BOTTOM + np.arange(NZ) * DZ
    ts["zRef"], ts["uRef"] = Z_HUB, U_HUB
    ts["ID"] = 7
    ts.write(str(Path(__file__).with_name("turbsim_small.bts")))
