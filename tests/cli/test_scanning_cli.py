"""`lidarjax simulate` and `lidarjax series` with a scanning `--scan` (a preset or the real Halo
file's layout): the CF NetCDF against the closed form ``u . n`` in a uniform wind (from the
file's own azimuth and elevation, per platform rotation), the series against
`simulate_scan_series` called directly, the VAD profile against the wind, the PNG, the region
read from each run, and the one-line refusals."""

from __future__ import annotations

import math

import numpy as np
import pytest
import xarray  # noqa: F401  (the test extra brings it)

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.cli._scanning import scan_region
from lidarjax.io import Settings, read_scan_netcdf, read_table_csv, save_field_npz, write_settings

from ..helpers import DATA, scanning_file, write_hpl

HPL = DATA / "scanning" / "RHI_77_20260921_000812.hpl"  # the committed real Halo RHI
WIND = np.array([3.0, -4.0, 0.5])  # uniform CFD wind, m/s
LOCATIONS = {0.0: [0.0, 0.0, 0.0], 30.0: [100.0, 50.0, 10.0]}
PNG = b"\x89PNG\r\n\x1a\n"


def _settings(path, betas):
    write_settings(path, Settings(zone=2, verbose=1, height=100.0, nh=2, gamma=0.0, beta=0.0,
                                  psi=0.0, epsilon=0.0, betas=np.array(betas),
                                  locations=np.array([LOCATIONS[b] for b in betas])))
    return path


def test_series_of_the_halo_file_layout(series_case, capsys):
    root, settings = series_case
    out = root / "hpl"
    assert main(["series", str(settings), *SERIES, "--scan", str(HPL), "--scans", "2",
                 "--no-plots", "--out", str(out)]) == 0
    back = read_scan_netcdf(out / "series_scan.nc")
    pattern = lj.io.read_hpl(HPL).pattern()
    assert back["radial_velocity"].shape == (2, 4, 20)
    times = np.asarray(pattern.ray_times())[None] + float(pattern.period) * np.arange(2)[:, None]
    np.testing.assert_allclose(back["ray_time"], times, atol=1e-9)
    assert np.isfinite(back["radial_velocity"]).all()
    assert "series_vad.csv" not in capsys.readouterr().out  # an RHI: no VAD profile
    assert not (out / "series_vad.csv").exists()


def _unit(back):
    """Body-frame rays ``(cos e sin a, cos e cos a, sin e)`` from the file's angles."""
    a, e = np.deg2rad(back["azimuth"]), np.deg2rad(back["elevation"])
    return np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=-1)


def _closed_form(back, beta):
    """``u . n`` per (beam, gate) from the file's azimuth and elevation: the body-frame ray
    turned by the platform rotation `beta` (degrees, anticlockwise) about z."""
    n = _unit(back)
    c, s = math.cos(math.radians(beta)), math.sin(math.radians(beta))
    n = n @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]).T
    return np.broadcast_to((n @ WIND)[:, None], back["radial_velocity"].shape[1:])


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("scanning_cli")
    settings = _settings(root / "settings.dat", [0.0, 30.0])
    x = y = np.linspace(-1500.0, 1500.0, 11)
    z = np.linspace(0.0, 1500.0, 6)
    vel = np.broadcast_to(WIND, (x.size, y.size, z.size, 3)).copy()
    for b in LOCATIONS:
        save_field_npz(root / f"run_{int(b)}.npz", (x, y, z, vel))
    return root, settings


@pytest.fixture(scope="module")
def ppi_run(case):
    root, settings = case
    out = root / "ppi"
    argv = ["simulate", str(settings), "--field", str(root / "run_{beta}.npz"), "--all",
            "--scan", "ppi", "--elevation", "5", "--n-rays", "12", "--gates", "8",
            "--probe", "pulsed", "--plot", "--out", str(out)]
    assert main(argv) == 0
    return out


def test_simulate_ppi_is_u_dot_n_per_beta_with_plots(ppi_run, capsys):
    for beta in (0.0, 30.0):
        back = read_scan_netcdf(ppi_run / f"scan_{int(beta)}.nc")
        assert back["radial_velocity"].shape == (1, 12, 8)
        np.testing.assert_allclose(back["elevation"], 5.0)
        np.testing.assert_allclose(back["range"], lj.scanning.gate_ranges(8, 30.0))
        np.testing.assert_allclose(back["radial_velocity"][0], _closed_form(back, beta),
                                   rtol=0, atol=1e-9)
        assert float(back["attrs"]["beta_deg"]) == beta
        assert (ppi_run / f"scan_{int(beta)}.png").read_bytes()[:8] == PNG


def test_simulate_hpl_layout_and_tilted_mount(case, tmp_path, capsys):
    root, settings = case
    out = tmp_path / "rhi"
    assert main(["simulate", str(settings), "--field", str(root / "run_0.npz"), "--beta", "0",
                 "--scan", str(HPL), "--probe", "pulsed", "--out", str(out)]) == 0
    line = capsys.readouterr().out
    assert "4 rays x 20 gates (rhi)" in line and "0.0% NaN" in line
    back = read_scan_netcdf(out / "scan_0.nc")
    halo = lj.io.read_hpl(HPL)
    pattern = halo.pattern()
    assert back["radial_velocity"].shape == (1, halo.n_rays, halo.n_gates)
    np.testing.assert_allclose(back["range"], halo.ranges)
    np.testing.assert_allclose(back["azimuth"], np.asarray(pattern.azimuth))
    np.testing.assert_allclose(back["elevation"], np.asarray(pattern.elevation))
    np.testing.assert_allclose(back["ray_time"][0], np.asarray(pattern.ray_times()))
    np.testing.assert_allclose(back["radial_velocity"][0], _closed_form(back, 0.0), atol=1e-9)
    # a tilted installation: the settings' mount with --pitch and --roll (rays leave the
    # mount's frame, so the LOS is no longer the file's u . n)
    argv = ["simulate", str(settings), "--field", str(root / "run_{beta}.npz"), "--beta", "30",
            "--scan", "rhi", "--azimuth", "40", "--n-rays", "5", "--gates", "4",
            "--pitch", "6", "--roll", "-4", "--out", str(out)]
    assert main(argv) == 0
    got = read_scan_netcdf(out / "scan_30.nc")["radial_velocity"][0]
    mount = lj.Mount(LOCATIONS[30.0], beta=30.0, pitch=6.0, roll=-4.0)
    pattern = lj.scanning.rhi(40.0, lj.scanning.gate_ranges(4, 30.0), n_rays=5)
    n = np.asarray(lj.scanning.simulate_scan(lj.scenes.uniform(5.0, 0.0), pattern,
                                             mount).directions)
    np.testing.assert_allclose(got, np.broadcast_to((n @ WIND)[:, None], got.shape), atol=1e-9)
    assert not np.allclose(got, _closed_form(read_scan_netcdf(out / "scan_30.nc"), 30.0))


def test_gates_beyond_the_run_are_nan_and_explained(case, tmp_path, capsys):
    root, settings = case
    argv = ["simulate", str(settings), "--field", str(root / "run_0.npz"), "--scan", "stare",
            "--azimuth", "90", "--elevation", "3", "--gates", "60", "--out", str(tmp_path)]
    assert main(argv) == 0
    los = read_scan_netcdf(tmp_path / "scan_0.nc")["radial_velocity"][0, 0]
    beyond = lj.scanning.gate_ranges(60, 30.0) * math.cos(math.radians(3.0)) > 1500.0
    assert beyond.sum() == 10
    np.testing.assert_array_equal(np.isnan(los), beyond)
    err = capsys.readouterr().err
    assert "10 of 60 gate centres lie outside the CFD field" in err and err.count("\n") == 1


def test_scan_region_bounds_the_gates_of_every_mount():
    pattern = lj.scanning.ppi(10.0, lj.scanning.gate_ranges(6, 30.0), n_rays=9)
    mounts = [lj.Mount(LOCATIONS[b], beta=b, pitch=3.0) for b in LOCATIONS]
    lo, hi = scan_region(pattern, mounts)  # point probe: exactly the gate centres' box
    pts = np.concatenate([np.asarray(lj.scanning.simulate_scan(
        lj.scenes.uniform(5.0, 0.0), pattern, m).points).reshape(-1, 3) for m in mounts])
    np.testing.assert_allclose(lo, pts.min(axis=0), atol=1e-9)
    np.testing.assert_allclose(hi, pts.max(axis=0), atol=1e-9)
    probe = lj.scanning.instrument_probe()  # pulsed: grows by its support along the beams
    lo_p, hi_p = scan_region(pattern, mounts, probe)
    assert np.all(lo_p < lo) and np.all(hi_p > hi)


@pytest.fixture(scope="module")
def series_case(tmp_path_factory):
    root = tmp_path_factory.mktemp("scanning_series")
    return root, _settings(root / "settings.dat", [0.0])


SERIES = ["--field", "uniform", "--speed", "8", "--direction", "270", "--generate-box",
          "32,8,8", "--box-spacing", "8,8,8", "--probe", "point"]


def test_series_matches_simulate_scan_series(series_case, capsys):
    root, settings = series_case
    out = root / "vad"
    # batches of 2 scans for 3: the second batch starts at 2 periods and is cut to one scan
    argv = ["series", str(settings), *SERIES, "--scan", "vad", "--elevation", "60",
            "--n-rays", "6", "--gates", "5", "--scans", "3", "--chunk", "2", "--out", str(out)]
    assert main(argv) == 0
    back = read_scan_netcdf(out / "series_scan.nc")
    field, _ = lj.series_field(lj.scenes.uniform(8.0, 270.0), LOCATIONS[0.0], speed=8.0,
                               direction=270.0, generate_box=(32, 8, 8), box_spacing=(8, 8, 8))
    pattern = lj.scanning.vad(60.0, lj.scanning.gate_ranges(5, 30.0), n_rays=6)
    ref = lj.scanning.simulate_scan_series(field, pattern, lj.Mount(LOCATIONS[0.0]), n_scans=3)
    assert back["radial_velocity"].shape == (3, 6, 5)
    np.testing.assert_allclose(back["radial_velocity"], np.asarray(ref.los), rtol=0, atol=1e-10)
    np.testing.assert_allclose(back["ray_time"], np.asarray(ref.times), rtol=0, atol=1e-12)
    period = float(pattern.period)
    np.testing.assert_allclose(back["ray_time"][:, 0] - back["ray_time"][0, 0],
                               [0.0, period, 2 * period])
    assert np.std(back["radial_velocity"]) > 0.1  # the turbulence is there
    table = read_table_csv(out / "series_vad.csv").columns
    prof = lj.scanning.vad_fit(back["radial_velocity"], back["azimuth"], back["elevation"],
                               back["range"])
    np.testing.assert_allclose(table["u"], np.asarray(prof.velocity)[..., 0].ravel())
    assert (out / "series_scan.png").read_bytes()[:8] == PNG
    assert "6 rays x 5 gates x 3 scans (vad)" in capsys.readouterr().out


def test_series_hours_and_vad_profile_of_a_calm_box(series_case, capsys):
    root, settings = series_case
    out = root / "ppi"
    argv = ["series", str(settings), *SERIES, "--ti", "1e-9", "--scan", "ppi", "--elevation",
            "30", "--n-rays", "8", "--accumulation", "0.5", "--gates", "3", "--hours", "0.005",
            "--no-plots", "--out", str(out)]
    assert main(argv) == 0
    back = read_scan_netcdf(out / "series_scan.nc")
    period = 8 * 0.5
    n = math.ceil(0.005 * 3600 / period)  # scans that cover --hours
    assert back["radial_velocity"].shape == (n, 8, 3)
    np.testing.assert_allclose(np.diff(back["ray_time"][:, 0]), period)
    wind = np.array([8.0, 0.0, 0.0])  # from 270: towards +x
    los = np.broadcast_to((_unit(back) @ wind)[:, None], back["radial_velocity"].shape)
    np.testing.assert_allclose(back["radial_velocity"], los, atol=1e-6)
    table = read_table_csv(out / "series_vad.csv").columns
    np.testing.assert_allclose(table["speed"], 8.0, atol=1e-6)
    np.testing.assert_allclose(table["direction"], 270.0, atol=1e-5)
    np.testing.assert_allclose(table["height"], np.tile(back["range"] * 0.5, n))
    assert not (out / "series_scan.png").exists()
    assert not (out / "series.sta").exists()
    capsys.readouterr()


@pytest.mark.parametrize("command, extra, text", [
    ("simulate", ["--scan", "ppi", "--cone-angle", "20"], "--cone-angle applies to the profilers"),
    ("simulate", ["--scan", "rhi", "--tilt-compensation"], "--tilt-compensation applies to"),
    ("simulate", ["--scan", "windcube_v2", "--elevation", "3"], "--elevation applies to scanning"),
    ("simulate", ["--scan", "zephir", "--plot"], "--plot draws a scanning scan"),
    ("simulate", ["--scan", "scan.txt"], "suffix '.txt' is no scan"),
    ("simulate", ["--scan", "spiral"], "'spiral' is no scan"),
    ("simulate", ["--scan", str(HPL), "--gates", "3"], "has its own"),
    ("simulate", ["--scan", "missing.hpl"], "not found"),
    ("simulate", ["--scan", "ppi", "--probe", "pulsed", "--probe-scale", "10"], "--gate-length"),
    ("series", ["--scan", "ppi", "--seconds-per-los", "1"], "--seconds-per-los"),
    ("series", ["--scan", "vad", "--cone-angle", "30"], "--cone-angle applies to the profilers"),
    ("series", ["--scan", "windcube_v2", "--scans", "3"], "--scans applies to scanning"),
    ("series", ["--scan", "windcube_v2", "--gate-length", "30"], "--gate-length applies to"),
])
def test_bad_inputs_are_one_line(case, tmp_path, capsys, command, extra, text):
    root, settings = case
    if command == "simulate":
        argv = ["simulate", str(settings), "--field", str(root / "run_0.npz")]
    else:
        argv = ["series", str(settings), *SERIES]
    rc = main(argv + extra + ["--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and text in err and "\n" not in err and "Traceback" not in err, err
    assert not (tmp_path / "o").exists()


def test_an_input_is_never_overwritten(case, tmp_path, capsys):
    root, settings = case
    field = tmp_path / "scan_0.nc"  # a CFD run named like the output of beta 0
    lj.io.save_field_netcdf(field, lj.io.load_field(root / "run_0.npz"))
    before = field.read_bytes()
    rc = main(["simulate", str(settings), "--field", str(field), "--scan", "stare",
               "--out", str(tmp_path)])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and "inputs are never overwritten" in err and "\n" not in err
    assert field.read_bytes() == before


def test_series_on_a_mesh_is_its_cellpoint_at_the_gates(tmp_path, capsys, monkeypatch):
    """`lidarjax series --scan` over an OpenFOAM mean flow (the real windAroundBuildings cut,
    a lidar on the roof) reads the mesh only over the scan's region and samples its own
    cellPoint at every gate, as `simulate --scan` does: with a calm box (TI 1e-9) each gate
    is ``n . U`` of OpenFOAM's cellPoint there (`sample_openfoam`, numpy) to 1e-7 m/s; the
    graded grid alone is off by more."""
    import foamlib  # noqa: F401  (the test extra brings it)

    from lidarjax.io import load_field
    from lidarjax.io.openfoam import read_openfoam_field, sample_openfoam

    from ._roof import CASE as case
    from ._roof import ROOF as roof
    from ._roof import record_regions, roof_settings

    regions = record_regions(monkeypatch)
    settings = roof_settings(tmp_path / "settings.dat", nh=1)
    out = tmp_path / "out"
    argv = ["series", str(settings), "--field", str(case), "--speed", "5", "--direction", "270",
            "--generate-box", "8,4,4", "--box-spacing", "40,40,40", "--ti", "1e-9",
            "--probe", "point", "--scan", "ppi", "--elevation", "40", "--n-rays", "8",
            "--gates", "6", "--gate-length", "3", "--accumulation", "0.5", "--scans", "1",
            "--no-plots", "--out", str(out)]
    assert main(argv) == 0
    assert "exact cellPoint" in capsys.readouterr().out
    back = read_scan_netcdf(out / "series_scan.nc")
    az, el = np.deg2rad(back["azimuth"]), np.deg2rad(back["elevation"])
    n = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)  # (r, 3)
    pts = np.asarray(roof) + back["range"][None, :, None] * n[:, None, :]  # (r, g, 3)
    of = read_openfoam_field(case)
    expect = np.einsum("rgi,ri->rg", sample_openfoam(of, pts.reshape(-1, 3)).reshape(pts.shape), n)
    got = back["radial_velocity"][0]
    (lo, hi), = regions  # the gates and the advection's height (10 m) above the lidar
    assert np.all(pts >= lo - 1e-9) and np.all(pts <= hi + 1e-9)
    assert hi[2] >= roof[2] + 10.0 and np.all(hi - lo < 40.0)
    assert np.isfinite(expect).sum() > 20
    np.testing.assert_array_equal(np.isnan(got), np.isnan(expect))
    np.testing.assert_allclose(got, expect, rtol=0, atol=1e-7)
    grid = load_field(case)
    pattern = lj.scanning.ppi(40.0, back["range"], n_rays=8, accumulation=0.5)
    graded = np.asarray(lj.scanning.simulate_scan(grid, pattern, lj.Mount(roof)).los)
    assert np.nanmax(np.abs(graded - expect)) > 1e-3


def _hour_of_vad(path):
    """An hour of a 6-ray VAD at 75 degrees (a scan every 300 s, rays 8 s apart, 5 gates of
    30 m) written in the real Halo layout: (file, ray seconds from the first ray)."""
    seconds = (np.arange(12)[:, None] * 300.0 + np.arange(6)[None] * 8.0).ravel()
    az = (np.arange(72) * 60.0 + np.repeat(np.arange(12) * 7.0, 6)) % 360
    write_hpl(path, hours=9.0 + seconds / 3600, azimuth=az, elevation=np.full(72, 75.0),
              doppler=np.zeros((72, 5)), scan_type="VAD", rays_per_scan=6)
    return path, seconds


def test_simulate_an_hour_of_vad_every_ray_at_its_own_time(case, tmp_path, capsys):
    """`simulate --scan FILE.hpl` of a one-hour file: every ray of its 12 scans, each at its
    own time (the file's, independent of the reader: from the hours written) and angles."""
    root, settings = case
    hpl, seconds = _hour_of_vad(tmp_path / "VAD_99_20240301_090000.hpl")
    out = tmp_path / "hour"
    assert main(["simulate", str(settings), "--field", str(root / "run_0.npz"), "--beta", "0",
                 "--scan", str(hpl), "--out", str(out)]) == 0
    assert "72 rays x 5 gates (vad)" in capsys.readouterr().out
    back = read_scan_netcdf(out / "scan_0.nc")
    assert back["radial_velocity"].shape == (1, 72, 5)
    # ray times: the middle of each 1 s accumulation ending at the ray's time (the file
    # holds 8 decimals of an hour: 18 us)
    np.testing.assert_allclose(back["ray_time"][0], seconds + 0.5, atol=2e-5)
    assert back["ray_time"][0][-1] > 3300.0
    np.testing.assert_allclose(back["radial_velocity"][0], _closed_form(back, 0.0), atol=1e-9)
    # series flies the same hour (one repetition) with the same ray times
    settings_s = _settings(tmp_path / "s.dat", [0.0])
    assert main(["series", str(settings_s), *SERIES, "--scan", str(hpl), "--scans", "1",
                 "--no-plots", "--out", str(tmp_path / "series")]) == 0
    got = read_scan_netcdf(tmp_path / "series" / "series_scan.nc")
    np.testing.assert_allclose(got["ray_time"][0], seconds + 0.5, atol=2e-5)
    assert got["radial_velocity"].shape == (1, 72, 5) and np.isfinite(got["radial_velocity"]).all()
    # one VAD profile per scan of the file (12 x 5 gates), each from its own 6 rays
    table = read_table_csv(tmp_path / "series" / "series_vad.csv").columns
    np.testing.assert_array_equal(table["scan"], np.repeat(np.arange(12), 5))
    np.testing.assert_array_equal(table["n_rays"], 6)
    np.testing.assert_allclose(table["time"][::5], got["ray_time"][0].reshape(12, 6).mean(axis=1))
    los, az = got["radial_velocity"][0].reshape(12, 6, 5), got["azimuth"].reshape(12, 6)
    prof = lj.scanning.vad_fit(los[7], az[7], 75.0, got["range"])  # the eighth scan alone
    np.testing.assert_allclose(table["u"][35:40], np.asarray(prof.velocity)[:, 0], atol=1e-9)


def test_simulate_the_real_two_scan_stare(case, tmp_path, capsys):
    """The real Eriswil stare (header 1 ray per scan, 2 held): both rays, 2.02 s apart."""
    root, settings = case
    hpl = scanning_file("Stare_91_20221214_11.hpl")
    assert main(["simulate", str(settings), "--field", str(root / "run_0.npz"), "--beta", "0",
                 "--scan", str(hpl), "--probe", "point", "--out", str(tmp_path)]) == 0
    back = read_scan_netcdf(tmp_path / "scan_0.nc")
    assert back["radial_velocity"].shape[:2] == (1, 2)
    np.testing.assert_allclose(np.diff(back["ray_time"][0]), 2.020032, atol=1e-5)
