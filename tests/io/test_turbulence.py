"""Turbulence-box files: TurbSim .bts (fixture written by OpenFAST's own Python writer) and
HAWC2 Mann binary (written by hipersim)."""


import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from lidarjax import scenes
from lidarjax.io import read_hawc2_box, read_turbsim, write_hawc2_box, write_turbsim
from lidarjax.scenes import FrozenTurbulence
from lidarjax.turbulence import TurbulenceBox, mann_box

from ..data import make_turbsim_fixture as fx
from ..helpers import DATA

BTS = DATA / "turbsim_small.bts"
sample_at = eqx.filter_jit(lambda f, p, t: f.sample_local_at(p, t))


def test_read_turbsim_fixture_matches_closed_form():
    ts = read_turbsim(BTS)
    want = fx.turbsim_fixture_velocity()
    assert ts.velocity.shape == (fx.NT, fx.NY, fx.NZ, 3)
    np.testing.assert_allclose(ts.y, (np.arange(fx.NY) - 2) * fx.DY)
    np.testing.assert_allclose(ts.z, fx.Z_BOTTOM + np.arange(fx.NZ) * fx.DZ)
    assert ts.dt == pytest.approx(fx.DT) and not ts.periodic and ts.tower.shape == (fx.NT, 0, 3)
    assert "TurbSimFile" in ts.description
    # int16 quantisation: one step of each component's range / 65535 (the writer truncates)
    step = (want.max(axis=(0, 1, 2)) - want.min(axis=(0, 1, 2))) / 65535
    assert np.all(np.abs(ts.velocity - want) <= 1.01 * step)


def test_read_turbsim_agrees_with_openfast_reader():
    from openfast_io import turbsim_file
    ref = turbsim_file.TurbSimFile(str(BTS))
    ts = read_turbsim(BTS)
    np.testing.assert_allclose(ts.velocity, np.moveaxis(ref["u"], 0, -1), rtol=0, atol=1e-6)
    assert ts.u_hub == pytest.approx(ref["uRef"]) and ts.z_hub == pytest.approx(ref["zRef"])


def test_write_turbsim_round_trip(tmp_path):
    rng = np.random.default_rng(3)
    vel = rng.normal(size=(6, 3, 4, 3)) + np.array([8.0, 0.0, 0.0])
    path = write_turbsim(tmp_path / "a.bts", vel, dy=2.0, dz=3.0, dt=0.5, z_bottom=10.0,
                         u_hub=8.0, z_hub=14.5, periodic=True)
    ts = read_turbsim(path)
    step = (vel.max(axis=(0, 1, 2)) - vel.min(axis=(0, 1, 2))) / 65535
    assert np.all(np.abs(ts.velocity - vel) <= 0.51 * step) and ts.periodic
    from openfast_io import turbsim_file
    ref = turbsim_file.TurbSimFile(str(path))
    np.testing.assert_allclose(np.moveaxis(ref["u"], 0, -1), ts.velocity, atol=1e-6)


def test_turbsim_box_is_taylor_consistent():
    """A point at the box's x = 0 sees plane n at t = n dt (as OpenFAST's InflowWind does)."""
    ts = read_turbsim(BTS)
    box = ts.box()
    assert box.shape == (fx.NT, fx.NY, fx.NZ)
    np.testing.assert_allclose(np.asarray(box.spacing), [ts.u_hub * ts.dt, fx.DY, fx.DZ], rtol=1e-6)
    fluct = ts.velocity - ts.velocity.mean(axis=0)
    f = FrozenTurbulence(scenes.uniform(0.0, 270.0), box, ts.u_hub, 270.0, anchor=(0.0, 0.0, ts.z[0]))
    # CFD point (0, y, z): box y = CFD y for wind from the west (box y to the left = north)
    j, k = 1, 2
    p = jnp.asarray([[0.0, ts.y[j], ts.z[k]]])
    n = np.array([0, 1, 5, 11])
    got = np.asarray(sample_at(f, p, jnp.asarray(n * ts.dt)))
    np.testing.assert_allclose(got, fluct[n, j, k], atol=1e-9)
    with pytest.raises(ValueError, match="speed"):
        ts.box(speed=0.0)


def test_turbsim_bad_files(tmp_path):
    raw = BTS.read_bytes()
    short = tmp_path / "short.bts"
    short.write_bytes(raw[:-10])
    with pytest.raises(ValueError, match="short.bts: size"):
        read_turbsim(short)
    bad = tmp_path / "bad.bts"
    bad.write_bytes(b"\x05\x00" + raw[2:])
    with pytest.raises(ValueError, match="ID 5"):
        read_turbsim(bad)
    with pytest.raises(FileNotFoundError):
        read_turbsim(tmp_path / "none.bts")


def test_hawc2_box_from_hipersim(tmp_path):
    import hipersim
    shape, spacing = (16, 8, 4), (4.0, 3.0, 2.5)
    mtf = hipersim.MannTurbulenceField.generate(alphaepsilon=0.1, L=30.0, Gamma=3.2, Nxyz=shape,
                                                dxyz=spacing, seed=4, double_xyz=(False, False, False))
    mtf.to_hawc2(folder=str(tmp_path), basename="mann_")
    files = [tmp_path / f"mann_{c}.turb" for c in "uvw"]
    box = read_hawc2_box(*files, shape, spacing, periodic=True)
    want = np.moveaxis(np.asarray(mtf.uvw), 0, -1)
    np.testing.assert_allclose(np.asarray(box.velocity), want.astype(np.float32), rtol=0, atol=0)
    # lidarjax's generator wrapper gives the same box
    gen = mann_box(0.1, 30.0, 3.2, shape, spacing, seed=4, periodic=True)
    np.testing.assert_allclose(np.asarray(gen.velocity), want, rtol=1e-12, atol=1e-12)
    assert gen.periodic == (True, True)
    doubled = mann_box(0.1, 30.0, 3.2, shape, spacing, seed=4)  # hipersim's y/z doubling
    assert doubled.periodic == (False, False) and doubled.shape == shape
    # write back, hipersim reads it
    out = write_hawc2_box(box, *(tmp_path / f"back_{c}.bin" for c in "uvw"))
    back = hipersim.MannTurbulenceField.from_hawc2([str(p) for p in out], 0.1, 30.0, 3.2, shape,
                                                   spacing, 4, 0)
    np.testing.assert_array_equal(np.asarray(back.uvw), np.moveaxis(np.asarray(box.velocity), -1, 0))
    # reverse_x: a point at box x = 0 meets planes 0, 1, 2 ... in time
    rev = read_hawc2_box(*files, shape, spacing, periodic=True, reverse_x=True)
    f = FrozenTurbulence(scenes.uniform(0.0, 270.0), rev, 8.0, 270.0)
    p = jnp.asarray([[0.0, 0.0, 2 * spacing[2]]])  # box node (., (ny-1)/2 -> between 3 and 4, 2)
    got = np.asarray(sample_at(f, p, jnp.arange(3) * spacing[0] / 8.0))
    mid = 0.5 * (want[:, 3, 2] + want[:, 4, 2])
    np.testing.assert_allclose(got, mid[:3], atol=1e-6)


def test_hawc2_bad_size(tmp_path):
    box = TurbulenceBox(np.zeros((4, 3, 2, 3)), (1.0, 1.0, 1.0))
    files = write_hawc2_box(box, *(tmp_path / f"b{c}.bin" for c in "uvw"))
    with pytest.raises(ValueError, match=r"bu.bin: a 4 x 3 x 3 box needs 144 bytes .* has 96 bytes"):
        read_hawc2_box(*files, (4, 3, 3), (1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match="spacing"):
        read_hawc2_box(*files, (4, 3, 2), (1.0, 0.0, 1.0))
