"""`series_rews`: the REWS estimate from `simulate_series`' LOS of a nacelle or spinner lidar
against the independent path, `lidar_rews` on the same focus points, probe and measurement
times (identical geometry: equal to round-off), and against the rotor's REWS (uniform flow:
equal; frozen turbulence: the preview shift lines the estimate up with the REWS)."""

import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax import control as lc

HUB = np.array([0.0, 0.0, 150.0])
YAW = 262.0  # the rotor faces 8 degrees off a westerly wind
LIDAR = HUB + np.array([1.5, 0.5, 3.0])  # on the nacelle roof, a little off the hub
ROTOR = lc.rotor_disc(60.0, spacing=20.0)
PROBE = lj.PulsedProbe(gate_length=20.0, n_nodes=7)


def nacelle_mount():
    """Looking along the rotor axis: the lidar's +y turned to the rotor's heading."""
    return lj.Mount(LIDAR, beta=360.0 - YAW, pitch=-90.0)


@pytest.fixture(scope="module")
def box_field():
    box = lj.synthesize_box((64, 16, 16), (8.0, 8.0, 8.0), 0.5, 30.0, 3.0, seed=3)
    return lj.scenes.frozen_turbulence(lj.scenes.uniform(10.0, 270.0), box, 10.0, 270.0,
                                       anchor=(0.0, 0.0, 90.0))


def _rotor_frame(points_cfd):
    return (np.asarray(points_cfd) - HUB) @ np.asarray(lc.rotor_to_cfd(YAW))


def _focus_cfd(scan, mount, heights):
    """Independent focus points: the mount's frame chain applied to the body beams."""
    n = np.asarray(lj.rotate(lj.body_to_cfd_rotation(mount), scan.directions()))
    ranges = np.asarray(heights)[:, None] / np.asarray(scan.directions())[None, :, 2]
    return LIDAR + ranges[..., None] * n  # (h, b, 3)


def _latest(los_time, t):
    """Per (h, b), the latest LOS time at or before t (the sliding window's)."""
    lt = np.asarray(los_time)
    return np.max(np.where(lt <= t + 1e-9, lt, -np.inf), axis=0)


def _matched(field, focus, times, t_est, probe):
    """`lidar_rews` at `t_est` from nodes at `focus` (h, b, 3) measured at `times` (h, b)."""
    samples = lc.lidar_samples(_rotor_frame(focus.reshape(-1, 3)), lidar_position=_rotor_frame(LIDAR),
                               probe=probe, times=np.asarray(times).reshape(-1))
    return float(lc.lidar_rews(field, samples, hub=HUB, yaw=YAW, times=jnp.array([t_est]))[0])


@pytest.mark.parametrize("scan", [lj.nacelle_2beam(15.0), lj.nacelle_4beam(15.0), lj.zephir(15.0, 12)])
def test_uniform_flow_equals_rotor(scan):
    """12 m/s from 270 with w: symmetric beams estimate 12 cos(8 deg), the rotor's REWS."""
    field = lj.scenes.uniform(12.0, 270.0, w=0.5)
    circular = scan.method == "sine_fit"  # a CW circular scan: heights in turn, 3 rotations each
    span = 12.0 if circular else 3 * scan.n_beams
    series = lj.simulate_series(field, scan, nacelle_mount(), [80.0, 120.0], (0.0, span))
    res = lc.series_rews(series, scan, nacelle_mount(), hub=HUB, yaw=YAW, field=field, rotor=ROTOR)
    expected = 12.0 * np.cos(np.deg2rad(8.0))
    np.testing.assert_allclose(res.estimate, expected, rtol=1e-12)
    np.testing.assert_allclose(res.rews, expected, rtol=1e-12)
    # sliding: one per new LOS after the first scan; circular: one per visit of both heights
    assert res.estimate.shape == ((2,) if circular else (2 * scan.n_beams + 1,))
    if circular:
        return
    # the preview: mean focus distance upstream over U, less the mean age of the window's LOS
    x = np.mean(_rotor_frame(_focus_cfd(scan, nacelle_mount(), np.array([80.0, 120.0])))[..., 0])
    lead = x / expected - np.mean(np.arange(scan.n_beams))
    np.testing.assert_allclose(res.preview_time - res.time, lead, rtol=1e-12)


def test_sheared_veered_matches_lidar_rews():
    """Power-law shear with veer, pulsed probe, per complete scan: `lidar_rews` on the same
    nodes and times."""
    field = lj.scenes.power_law(10.0, 150.0, 0.2, 270.0, veer=0.1)
    scan, mount, heights = lj.nacelle_4beam(20.0), nacelle_mount(), np.array([60.0, 100.0, 140.0])
    series = lj.simulate_series(field, scan, mount, heights, (0.0, 8.0), probe=PROBE, refine_probe=False)
    res = lc.series_rews(series, scan, mount, hub=HUB, yaw=YAW, update="each_scan")
    assert res.estimate.shape == (2,) and res.rews is None
    focus = _focus_cfd(scan, mount, heights)
    for k in range(2):
        got = _matched(field, focus, series.los_time[k], float(res.time[k]), PROBE)
        assert float(res.estimate[k]) == pytest.approx(got, rel=1e-12)
    assert abs(float(res.estimate[0]) - 10.0) > 0.05  # shear and veer move it off the hub's 10 m/s


def test_frozen_turbulence_sliding(box_field):
    """Frozen turbulence, sliding windows: every estimate is `lidar_rews` with each beam at its
    latest LOS, and the rotor's REWS is `rotor_rews` at the preview times."""
    scan, mount, heights = lj.nacelle_4beam(15.0), nacelle_mount(), np.array([50.0, 90.0])
    series = lj.simulate_series(box_field, scan, mount, heights, (0.0, 24.0), probe=PROBE,
                                refine_probe=False)
    res = lc.series_rews(series, scan, mount, hub=HUB, yaw=YAW, field=box_field, rotor=ROTOR, speed=10.0)
    assert res.estimate.shape == (21,) and np.all(np.isfinite(res.estimate))
    focus = _focus_cfd(scan, mount, heights)
    for k in (0, 5, 14):
        t = float(res.time[k])
        got = _matched(box_field, focus, _latest(series.los_time, t), t, PROBE)
        assert float(res.estimate[k]) == pytest.approx(got, rel=1e-11)
    np.testing.assert_allclose(res.rews, lc.rotor_rews(box_field, ROTOR, hub=HUB, yaw=YAW,
                                                       times=res.preview_time), rtol=1e-12)
    assert float(jnp.std(res.estimate)) > 0.05  # a turbulent signal


def test_spinner_rosette(box_field):
    """A spinner lidar's rosette (`ScanResult`: rays as beams, gates as gates), CW probe:
    `lidar_rews` on the rays' gate centres at their times, one estimate per rosette."""
    pattern = lj.spinner_rosette([70.0, 110.0], n_points=24, duration=2.0, half_angle=20.0)
    mount = nacelle_mount()
    probe = lj.CWProbe(n_nodes=9)
    res_scan = lj.simulate_series(box_field, pattern, mount, None, (0.0, 4.0), probe=probe)
    res = lc.series_rews(res_scan, hub=HUB, yaw=YAW)
    assert res.estimate.shape == (2,)
    for k in range(2):
        focus = np.swapaxes(np.asarray(res_scan.points), 0, 1)  # (g, r, 3)
        times = np.broadcast_to(np.asarray(res_scan.times[k])[None], focus.shape[:2])
        got = _matched(box_field, focus, times, float(res.time[k]), probe)
        assert float(res.estimate[k]) == pytest.approx(got, rel=1e-10)


def test_bad_input():
    series = lj.simulate_series(lj.scenes.uniform(), lj.nacelle_2beam(), nacelle_mount(), [80.0], (0.0, 2.0))
    with pytest.raises(ValueError, match="needs the `scan`"):
        lc.series_rews(series, hub=HUB, yaw=YAW)
    with pytest.raises(ValueError, match="has 2 beams"):
        lc.series_rews(series, lj.nacelle_4beam(), nacelle_mount(), hub=HUB, yaw=YAW)
    with pytest.raises(ValueError, match="both `field` and `rotor`"):
        lc.series_rews(series, lj.nacelle_2beam(), nacelle_mount(), hub=HUB, yaw=YAW, field=lj.scenes.uniform())
    with pytest.raises(ValueError, match="`update`"):
        lc.series_rews(series, lj.nacelle_2beam(), nacelle_mount(), hub=HUB, yaw=YAW, update="sometimes")
    with pytest.raises(ValueError, match="Series or ScanResult"):
        lc.series_rews(np.zeros((4, 2)), hub=HUB, yaw=YAW)
    with pytest.raises(ValueError, match="`hub` must be"):
        lc.series_rews(series, lj.nacelle_2beam(), nacelle_mount(), hub=[0.0, 0.0], yaw=YAW)
    with pytest.raises(ValueError, match="is a batch"):
        lc.series_rews(series, lj.nacelle_2beam(), lj.Mount(np.zeros((2, 3)), pitch=-90.0), hub=HUB, yaw=YAW)
    with pytest.raises(ValueError, match="`schedule` must be"):
        lc.series_rews(series, lj.nacelle_2beam(), nacelle_mount(), hub=HUB, yaw=YAW, schedule="1 Hz")
