"""`lidarjax scan`: presets and real scan files through the command line, CF NetCDF out,
the PPI/RHI plot, one-line refusals."""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.io import read_scan_netcdf

from ..helpers import DATA

pytest.importorskip("xarray")


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
