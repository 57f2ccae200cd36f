"""`lidarjax scan`: presets and real scan files through the command line, CF NetCDF out,
the PPI/RHI plot, one-line refusals."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest
import xarray  # noqa: F401  (the test extra brings it)

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.io import read_scan_netcdf

from ..helpers import DATA


def test_ppi_preset_written_and_equal_to_the_api(tmp_path, capsys):
    out, png = tmp_path / "ppi.nc", tmp_path / "ppi.png"
    rc = main(["scan", "ppi", "--elevation", "4", "--n-rays", "12", "--gates", "10", "--wind", "8,250",
               "--point-probe", "--out", str(out), "--plot", str(png)])
    assert rc == 0 and png.stat().st_size > 0
    back = read_scan_netcdf(out)
    p = lj.ppi(4.0, lj.gate_ranges(10, 30.0), n_rays=12)
    ref = lj.simulate_scan(lj.scenes.uniform(8.0, 250.0), p, lj.Mount([0.0, 0.0, 0.0]))
    np.testing.assert_allclose(back["radial_velocity"][0], np.asarray(ref.los), atol=1e-12)
    assert "12 rays x 10 gates" in capsys.readouterr().out


def test_scan_file_layout_series_and_rhi_plot(tmp_path):
    out = tmp_path / "rhi_file.nc"
    hpl = DATA / "scanning" / "RHI_77_20260921_000812.hpl"  # the committed real Halo RHI
    assert main(["scan", str(hpl), "--scans", "2", "--out", str(out)]) == 0
    back = read_scan_netcdf(out)
    assert back["radial_velocity"].shape == (2, 4, 20)
    np.testing.assert_allclose(back["range"], lj.io.read_hpl(hpl).ranges)
    png = tmp_path / "rhi.png"
    assert main(["scan", "rhi", "--azimuth", "30", "--n-rays", "6", "--gates", "5",
                 "--out", str(tmp_path / "rhi.nc"), "--plot", str(png)]) == 0
    assert png.stat().st_size > 0


@pytest.mark.parametrize("argv, text", [
    (["scan", "spiral"], "neither a preset"),
    (["scan", "ppi", "--n-rays", "0"], "positive integer"),
    (["scan", "ppi", "--wind", "8"], "SPEED,DIRECTION"),
])
def test_bad_arguments_one_line(tmp_path, capsys, argv, text):
    rc = main(argv + ["--out", str(tmp_path / "x.nc")])
    err = capsys.readouterr().err.strip()
    assert rc == 2 and text in err and "\n" not in err


def test_scan_on_a_mesh_is_exact_at_its_nodes(tmp_path):
    """`lidarjax scan --field CASE` on an OpenFOAM case: read over the scan's region and exact
    (the mesh's cellPoint) at every node it samples: the same LOS as `simulate_scan` on the
    field prepared at `scan_points` (the API route of docs/scanning.md)."""
    from lidarjax.cli import build_parser
    from lidarjax.cli._scanning import read_scan_source, scan_region
    from lidarjax.scanning import instrument_probe, simulate_scan

    case = DATA / "openfoam" / "windAroundBuildings_cut"
    argv = ["scan", "ppi", "--elevation", "40", "--n-rays", "4", "--gates", "3",
            "--gate-length", "6", "--field", str(case), "--location", "96,126,39",
            "--out", str(tmp_path / "s.nc")]
    with contextlib.redirect_stdout(io.StringIO()):
        assert main(argv) == 0
    got = read_scan_netcdf(tmp_path / "s.nc")["radial_velocity"]
    pattern, gate = read_scan_source(build_parser().parse_args(argv))
    mount = lj.Mount([96.0, 126.0, 39.0])
    probe = instrument_probe("halo_streamline", gate_length=gate)
    region = scan_region(pattern, mount, probe)
    field = lj.io.load_field(case, region=region,
                             exact_at=lambda g: lj.scan_points(g, pattern, mount, probe))
    ref = np.asarray(simulate_scan(field, pattern, mount, probe=probe).los)
    assert np.isfinite(ref).sum() >= 6
    np.testing.assert_allclose(got.reshape(ref.shape), ref, rtol=0, atol=1e-9)


def test_polar_cells_are_the_gates_between_ray_edges_and_gate_ends():
    """Each gate a cell between its ray's edges (half-way to the neighbouring rays) and its
    gate's ends (half-way to the neighbouring gates), as radar displays draw them."""
    from lidarjax.cli._scanning import _edges, _polar_cells, _ray_half_widths

    np.testing.assert_allclose(_edges(np.array([15.0, 45.0, 75.0]), 30.0), [0, 30, 60, 90])
    np.testing.assert_allclose(_ray_half_widths(np.arange(6) * 60.0, circular=True), 30.0)
    np.testing.assert_allclose(_ray_half_widths(np.array([350.0, 0.0, 10.0]), circular=True), 5.0)
    np.testing.assert_allclose(_ray_half_widths(np.array([0.0, 15.0, 45.0]), circular=False),
                               [7.5, 7.5, 15.0])
    cells = _polar_cells(np.array([90.0]), np.array([5.0]), np.array([10.0, 20.0]), rhi=False,
                         steps=2)
    a = np.radians([85.0, 90.0, 95.0])
    near = np.stack([10 * np.sin(a), 10 * np.cos(a)], -1)
    far = np.stack([20 * np.sin(a), 20 * np.cos(a)], -1)[::-1]
    np.testing.assert_allclose(cells[0], np.concatenate([near, far]), atol=1e-12)
    rhi = _polar_cells(np.array([30.0]), np.array([15.0]), np.array([0.0, 10.0]), rhi=True, steps=2)
    np.testing.assert_allclose(rhi[0, -1], [10 * np.cos(np.radians(15)), 10 * np.sin(np.radians(15))])


def test_scan_file_plot_measured_beside_simulated_rejected_grey(tmp_path):
    """`lidarjax scan FILE --plot`: the file's own Doppler (intensity threshold applied)
    beside the simulation, rejected gates grey, one diverging scale centred on zero."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from lidarjax.cli._scanning import _scan_panel, measured_los, scan_geometry

    hpl = DATA / "scanning" / "RHI_77_20260921_000812.hpl"
    png = tmp_path / "rhi.png"
    assert main(["scan", str(hpl), "--out", str(tmp_path / "r.nc"), "--plot", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    halo = lj.io.read_hpl(hpl)
    los, title = measured_los(halo)
    rejected = halo.intensity < lj.io.hpl.INTENSITY_THRESHOLD
    assert rejected.sum() == 44 and np.all(np.isnan(los) == rejected) and "1.015" in title
    res = lj.simulate_scan(lj.scenes.uniform(8.0, 250.0), halo.pattern(), lj.Mount([0.0, 0.0, 0.0]))
    az, el, ranges, _ = scan_geometry(res)
    np.testing.assert_allclose(el, halo.elevation, atol=1e-9)
    np.testing.assert_allclose(az[1:], 255.0 - 360.0, atol=1e-9)  # clockwise from +y
    fig, ax = plt.subplots()
    cmap = matplotlib.colormaps["RdBu_r"].with_extremes(bad="0.75")
    norm = matplotlib.colors.Normalize(-5.0, 5.0)
    coll = _scan_panel(ax, (az, el, ranges, None), los, "rhi", norm, cmap, title)
    fig.canvas.draw()
    colours = coll.get_facecolors().reshape(4, 20, 4)
    np.testing.assert_allclose(colours[rejected], [[0.75, 0.75, 0.75, 1.0]] * 44)
    kept = ~rejected
    np.testing.assert_allclose(colours[kept], cmap(norm(los[kept])), atol=1e-12)
    # zero is the white centre of the diverging map
    np.testing.assert_allclose(cmap(norm(0.0))[:3], cmap(0.5)[:3])
    plt.close(fig)
