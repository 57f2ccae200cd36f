"""Snapshot sequences from files (issue 20, point 6): OpenFOAM time directories, field files,
NetCDF with a time axis; and a real pimpleFoam transient flown through by `simulate_series`,
checked against OpenFOAM's own probes at the same times (committed outputs, recipe in
tests/data/openfoam_transient/README.md)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import load_field_sequence, sample_openfoam, save_field_npz
from lidarjax.io.monitor_points import read_openfoam_probes
from tests._foamwrite import hex_mesh, write_polymesh, write_vector_field

DATA = Path(__file__).resolve().parents[1] / "data" / "openfoam_transient" / "case"


def _flow(p, t):
    return np.stack([8.0 + 0.02 * p[..., 2] + 0.1 * t, 0.5 + 0.01 * p[..., 0] - 0.05 * t,
                     0.001 * t + 0.0 * p[..., 1]], axis=-1)


def test_openfoam_time_directories_become_one_field(tmp_path):
    ax = np.linspace(0.0, 40.0, 9)
    m = hex_mesh(ax, ax, ax * 0.5)
    write_polymesh(tmp_path, m["points"], m["face_offsets"], m["face_labels"], m["owner"],
                   m["neighbour"], m["patches"], binary=True)
    bnd = {name: ("zeroGradient", None) for name, *_ in m["patches"]}
    for t in ("0", "0.5", "1", "2"):
        write_vector_field(tmp_path, t, "U", _flow(m["cell_centres"], float(t)), bnd, binary=True)
    (tmp_path / "system").mkdir()
    seq = load_field_sequence(tmp_path)
    np.testing.assert_array_equal(seq.times, [0.0, 0.5, 1.0, 2.0])
    win = seq.window(0, 3)
    # every snapshot on the first one's nodes, each the mesh's own cellPoint there
    pts = np.stack(np.meshgrid(*(np.asarray(a) for a in (win.grid.x, win.grid.y, win.grid.z)),
                               indexing="ij"), axis=-1).reshape(-1, 3)
    for k, t in enumerate(seq.times):
        ref = sample_openfoam(tmp_path, pts, time=t)
        got = np.asarray(win.snapshot(k).velocity).reshape(-1, 3)
        ok = np.isfinite(ref).all(axis=1)
        np.testing.assert_allclose(got[ok], ref[ok], atol=1e-12)
    sub = load_field_sequence(tmp_path, time_range=(0.4, 2.0))
    np.testing.assert_array_equal(sub.times, [0.5, 1.0, 2.0])
    with pytest.raises(ValueError, match="at least two snapshots"):
        load_field_sequence(tmp_path, time_range=(1.5, 9.0))
    with pytest.raises(ValueError, match="time_range"):
        load_field_sequence(tmp_path, times=[0, 1, 2, 3])


def test_field_files_and_netcdf_with_a_time_axis(tmp_path):
    x, y, z = np.linspace(0, 50, 6), np.linspace(0, 40, 5), np.linspace(0, 30, 4)
    pts = np.stack(np.meshgrid(x, y, z, indexing="ij"), axis=-1)
    times = [0.0, 1.0, 3.0]
    paths = []
    for k, t in enumerate(times):
        paths.append(save_field_npz(tmp_path / f"snap_{k}.npz", (x, y, z, _flow(pts, t))))
    seq = load_field_sequence(paths, times=times)
    same = load_field_sequence(str(tmp_path / "snap_*.npz"), times=times)
    f = seq.window(0, 2)
    q = np.array([[12.0, 7.0, 21.0]])
    got = np.asarray(f.sample_local_at(q - np.asarray(f.origin), 2.2))
    np.testing.assert_allclose(got, _flow(q, 2.2), atol=1e-12)
    np.testing.assert_allclose(np.asarray(same.window(0, 2).grid.velocity),
                               np.asarray(f.grid.velocity))
    with pytest.raises(ValueError, match="3 files but 2 times"):
        load_field_sequence(paths, times=times[:2])
    with pytest.raises(ValueError, match="give `times`"):
        load_field_sequence(paths)
    xr = pytest.importorskip("xarray")
    vel = np.stack([_flow(pts, t) for t in times])
    ds = xr.Dataset({c: (("time", "x", "y", "z"), vel[..., i]) for i, c in enumerate("uvw")},
                    coords={"time": times, "x": x, "y": y, "z": z})
    nc = tmp_path / "run.nc"
    ds.to_netcdf(nc)
    seq_nc = load_field_sequence(nc)
    np.testing.assert_array_equal(seq_nc.times, times)
    np.testing.assert_allclose(np.asarray(seq_nc.window(0, 2).grid.velocity),
                               np.asarray(f.grid.velocity))


@pytest.fixture(scope="module")
def transient():
    """The committed pimpleFoam run flown through by a Windcube V2 (point probe)."""
    scan, mount = lj.windcube_v2(), lj.Mount([150.0, 60.0, 0.0])
    heights = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0])
    seq = load_field_sequence(DATA, region=lj.scan_bounds(scan, mount, heights), spacing=1.0)
    series = lj.simulate_series(seq, scan, mount, heights, (10.0, 20.0))
    probes = read_openfoam_probes(DATA / "postProcessing" / "lidarProbes")
    mp = lj.monitor_points(scan, mount, heights)
    return seq, series, probes, mp, heights


def test_pimplefoam_run_matches_its_own_probes_at_the_lidars_times(transient):
    """Each LOS at its own time against OpenFOAM's probes (cellPoint, every 0.5 s step) at
    the same point, projected on the beam (independent geometry: from the lidar to the
    probe): within 0.03 m/s of the probes interpolated linearly between the snapshot times
    (what the sequence represents: the rest is the 1 m grid's resampling of cellPoint next
    to the no-slip ground), and within 0.05 m/s of the probes at every step (adding the
    2-s snapshots' interpolation in time)."""
    seq, s, probes, mp, heights = transient
    assert len(seq) == 11 and seq.time_span == (10.0, 30.0)
    los, t_los = np.asarray(s.los), np.asarray(s.los_time)
    assert np.isfinite(los).all() and not np.asarray(s.los_flags).any()
    lidar = np.array([150.0, 60.0, 0.0])
    snap = np.arange(10.0, 30.1, 2.0)
    rows = [int(np.argmin(np.abs(probes.times - t))) for t in snap]
    err_snap, err_step = [], []
    for i, h in enumerate(heights):
        for b in range(5):
            j = int(np.flatnonzero((mp.height == h) & (mp.beam == b))[0])
            d = probes.header_points[j] - lidar
            n = d / np.linalg.norm(d)
            series_j = probes.values[:, j] @ n
            err_step.append(np.abs(los[:, i, b] - np.interp(t_los[:, i, b], probes.times, series_j)))
            err_snap.append(np.abs(los[:, i, b] - np.interp(t_los[:, i, b], snap, series_j[rows])))
    assert np.max(err_snap) < 0.03 and np.max(err_step) < 0.05, (np.max(err_snap), np.max(err_step))
    # the flow really changes over the run: the inflow ramps 6 -> 10 m/s
    assert np.ptp(np.asarray(s.point_velocity)[:, -1, 0]) > 0.5


def test_pimplefoam_snapshots_are_the_meshs_cellpoint(transient):
    """At a snapshot time the sequence's grid holds the mesh's own cellPoint values, which
    equal OpenFOAM's probes to 1e-9 m/s."""
    seq, _, probes, mp, _ = transient
    k = int(np.argmin(np.abs(probes.times - 20.0)))
    ref = sample_openfoam(DATA, probes.header_points, time=20)
    np.testing.assert_allclose(ref, probes.values[k], atol=1e-9)
