"""Snapshot sequences from files (issue 20, point 6): OpenFOAM time directories, field files,
NetCDF with a time axis; and a real pimpleFoam transient flown through by `simulate_series`,
checked against OpenFOAM's own probes at the same times (committed outputs, recipe in
tests/data/openfoam_transient/README.md)."""

from __future__ import annotations

import gc
import re
import sys
import warnings
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import load_field_sequence, sample_openfoam, save_field_npz
from lidarjax.io.monitor_points import read_openfoam_probes
from tests._foamwrite import hex_mesh, write_polymesh, write_vector_field
from tests._transient import probe_los

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
    import xarray as xr
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
    """The committed pimpleFoam run flown through by a Windcube V2 (point probe): the default
    call (no `exact_at`, the automatic graded grid)."""
    scan, mount = lj.windcube_v2(), lj.Mount([150.0, 60.0, 0.0])
    heights = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0])
    seq = load_field_sequence(DATA, region=lj.scan_bounds(scan, mount, heights))
    series = lj.simulate_series(seq, scan, mount, heights, (10.0, 20.0))
    probes = read_openfoam_probes(DATA / "postProcessing" / "lidarProbes")
    mp = lj.monitor_points(scan, mount, heights)
    return seq, series, probes, mp, heights


def test_pimplefoam_run_matches_its_own_probes_at_the_lidars_times(transient):
    """Each LOS at its own time against OpenFOAM's probes (cellPoint, every 0.5 s step) at
    the same point, projected on the beam (independent geometry: from the lidar to the
    probe). The default call is exact for a fixed lidar (issue 37: the automatic graded
    grid alone is 0.25 m/s off next to the no-slip ground): within 1e-5 m/s of the probes
    interpolated linearly between the snapshot times (what the sequence represents) at
    every height, 10 m included, and within 0.05 m/s of the probes at every step (adding the
    2-s snapshots' interpolation in time)."""
    seq, s, probes, mp, heights = transient
    assert len(seq) == 11 and seq.time_span == (10.0, 30.0)
    los, t_los = np.asarray(s.los), np.asarray(s.los_time)
    assert np.isfinite(los).all() and not np.asarray(s.los_flags).any()
    lidar = np.array([150.0, 60.0, 0.0])
    snap = np.arange(10.0, 30.1, 2.0)
    rows = [int(np.argmin(np.abs(probes.times - t))) for t in snap]
    err_snap, err_step = np.zeros(heights.size), []
    for i, h in enumerate(heights):
        for b in range(5):
            j = int(np.flatnonzero((mp.height == h) & (mp.beam == b))[0])
            d = probes.header_points[j] - lidar
            n = d / np.linalg.norm(d)
            series_j = probes.values[:, j] @ n
            err_step.append(np.abs(los[:, i, b] - np.interp(t_los[:, i, b], probes.times, series_j)))
            err_snap[i] = max(err_snap[i], np.max(np.abs(
                los[:, i, b] - np.interp(t_los[:, i, b], snap, series_j[rows]))))
    assert err_snap.max() < 1e-5 and np.max(err_step) < 0.05, (err_snap, np.max(err_step))
    assert seq.can_be_exact  # loaded without exact_at: simulate_series prepared the points
    # the flow really changes over the run: the inflow ramps 6 -> 10 m/s
    assert np.ptp(np.asarray(s.point_velocity)[:, -1, 0]) > 0.5


def test_pimplefoam_snapshots_are_the_meshs_cellpoint(transient):
    """At a snapshot time the sequence's grid holds the mesh's own cellPoint values, which
    equal OpenFOAM's probes to 1e-9 m/s."""
    seq, _, probes, mp, _ = transient
    k = int(np.argmin(np.abs(probes.times - 20.0)))
    ref = sample_openfoam(DATA, probes.header_points, time=20)
    np.testing.assert_allclose(ref, probes.values[k], atol=1e-9)


# ---------------------------------------------------------------- exact at prepared points
# (issue 31, point 2): the sequence answers the points the run samples from their cellPoint
# tetrahedra, found once; each snapshot is its velocity read once and a sparse product.

HEIGHTS = np.array([10.0, 20.0, 30.0, 40.0, 50.0, 60.0])


def _probe_errors(series, probes, mp, heights):
    """Per height: max |LOS - OpenFOAM's probes interpolated between the snapshot times|,
    the probes projected on the beam from the lidar (independent geometry)."""
    los, t_los = np.asarray(series.los), np.asarray(series.los_time)
    err = np.zeros(heights.size)
    for i, h in enumerate(heights):
        for b in range(5):
            ref = probe_los(probes, mp, h, b, t_los[:, i, b])
            err[i] = max(err[i], np.max(np.abs(los[:, i, b] - ref)))
    return err


def test_pimplefoam_exact_sequence_matches_probes_at_every_height(transient):
    """The committed pimpleFoam run with the automatic graded grid (0.25 m/s off next to the
    no-slip ground through the grid alone) made exact at the Windcube's points, here by
    `exact_at` without the grid per snapshot (a fixed lidar samples only its prepared
    points): the LOS of the default call (exact, within 1e-5 m/s of OpenFOAM's probes at
    every height: the test above); a query elsewhere is NaN."""
    seq, s, _, _, heights = transient
    scan, mount = lj.windcube_v2(), lj.Mount([150.0, 60.0, 0.0])
    lean = load_field_sequence(DATA, region=lj.scan_bounds(scan, mount, heights),
                               exact_at=lj.io.simulate_points(scan, mount, heights),
                               grid_fallback=False)
    assert isinstance(lean.window(0, 1), lj.io.CellPointSnapshots) and not lean.can_be_exact
    s2 = lj.simulate_series(lean, scan, mount, heights, (10.0, 20.0))
    np.testing.assert_allclose(np.asarray(s2.los), np.asarray(s.los), rtol=0, atol=1e-12)
    w = lean.window(0, 1)
    assert w.resolution == seq.window(0, 1).resolution
    assert np.isnan(np.asarray(w.sample_local_at(jnp.ones(3), 0.5))).all()


def _transient_copy(tmp_path, keep=("10", "12", "14", "16", "18")):
    """The committed transient's mesh and the snapshots `keep`, in `tmp_path`."""
    import shutil

    case = tmp_path / "case"
    for d in ("constant", "system", *keep):
        shutil.copytree(DATA / d, case / d)
    return case


def test_each_snapshot_read_once_and_bad_time_directories_flagged(tmp_path, monkeypatch):
    """Every velocity file is read once however the windows overlap; a time directory with a
    changed mesh, a truncated file or non-finite values gives a one-line warning naming it
    and a NaN snapshot (the LOS next to it NaN and flagged), the good snapshots kept and
    exact (OpenFOAM's probes at 10 and 12 s)."""
    from lidarjax.io import snapshots

    case = _transient_copy(tmp_path, ("10", "12", "14", "16", "18", "20", "22"))
    (case / "14" / "polyMesh").mkdir()                            # the mesh changes at 14
    data = (case / "18" / "U").read_bytes()
    (case / "18" / "U").write_bytes(data[: len(data) // 2])       # truncated
    reads = []
    real = snapshots._read_vector_field
    monkeypatch.setattr(snapshots, "_read_vector_field",
                        lambda path, mesh: reads.append(path.parent.name) or real(path, mesh))
    scan, mount = lj.windcube_v2(), lj.Mount([150.0, 60.0, 0.0])
    h = HEIGHTS[:2]
    seq = load_field_sequence(case, region=lj.scan_bounds(scan, mount, h), max_snapshots=4,
                              exact_at=lj.io.simulate_points(scan, mount, h))
    with pytest.warns(UserWarning) as caught:
        s = lj.simulate_series(seq, scan, mount, h, (10.0, 12.0))
    msgs = [str(w.message) for w in caught]
    assert any(f"{case / '14' / 'polyMesh'}: the mesh changes at time 14" in m for m in msgs)
    assert any(str(case / "18") in m for m in msgs)
    assert all("\n" not in m for m in msgs)
    assert sorted(reads) == sorted(set(reads)), reads  # each file once
    los, t, flags = np.asarray(s.los), np.asarray(s.los_time), np.asarray(s.los_flags)
    good = t <= 12.0
    bad = ((t > 12.0) & (t < 16.0)) | ((t > 16.0) & (t < 20.0))
    assert good.any() and bad.any()
    assert np.isfinite(los[good]).all() and not flags[good].any()
    assert np.isnan(los[bad]).all() and (flags[bad] & int(lj.Flag.BEAM_OUTSIDE)).all()
    assert np.isfinite(los[(t > 20.0) & (t <= 22.0)]).all()
    probes = read_openfoam_probes(DATA / "postProcessing" / "lidarProbes")
    err = _probe_errors_window(s, probes, lj.monitor_points(scan, mount, h), h, good)
    assert err < 1e-5, err


def _probe_errors_window(series, probes, mp, heights, mask):
    los, t_los = np.asarray(series.los), np.asarray(series.los_time)
    err = 0.0
    for i, h in enumerate(heights):
        for b in range(5):
            ref = probe_los(probes, mp, h, b, t_los[:, i, b])
            m = mask[:, i, b]
            err = max(err, float(np.max(np.abs(los[m, i, b] - ref[m]), initial=0.0)))
    return err


def test_nonfinite_snapshot_is_flagged_not_fatal(tmp_path):
    """A snapshot with a non-finite cell value where the prepared points use it: one warning
    naming its file, NaN there. With no grid, a non-finite value in a cell no prepared point
    uses flags nothing: the snapshot's values at the points are exact."""
    case = _transient_copy(tmp_path, ("10", "12", "14"))
    from lidarjax.io.openfoam import _read_vector_field, read_openfoam_mesh
    from tests._foamwrite import write_vector_field

    scan, mount = lj.windcube_v2(), lj.Mount([150.0, 60.0, 0.0])
    pts = lj.io.simulate_points(scan, mount, HEIGHTS[:1])
    of = lj.io.read_openfoam_field(case, time="12")
    near = of.cells_in_box(pts[0], pts[0])  # the cells around the first point
    lo, hi = of.bounds
    far = int(np.argmax(np.min(np.linalg.norm(0.5 * (lo + hi)[:, None] - pts[None], axis=2),
                               axis=1)))  # the cell farthest from every point
    mesh = read_openfoam_mesh(case)
    good, _ = _read_vector_field(case / "12" / "U", mesh)
    bnd = {name: ("zeroGradient", None) for name, *_ in mesh.patches}

    def window(bad_cells):
        values = good.copy()
        values[bad_cells, 0] = np.inf
        write_vector_field(case, "12", "U", values, bnd, binary=False)
        seq = load_field_sequence(case, exact_at=pts, grid_fallback=False,
                                  region=lj.scan_bounds(scan, mount, HEIGHTS[:1]))
        w = seq.window(0, 2)
        o = np.asarray(w.origin, np.float64) + np.asarray(w.origin_lo, np.float64)
        t = np.asarray(w.times, np.float64)  # between the snapshots, at the bad one, between
        q = np.array([(t[0] + t[1]) / 2, t[1], (t[1] + t[2]) / 2])
        return np.asarray(w.sample_local_at(jnp.asarray(pts - o), jnp.asarray(q)[:, None]))

    with pytest.warns(UserWarning, match=rf"12/U: {near.size} cell values are not finite"):
        v = window(near)
    assert np.isnan(v[[0, 2]]).all()  # both intervals touch the bad snapshot
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        v = window([far])
    ref = sample_openfoam(case, pts, time="12")  # the far cell: no point's value
    assert np.isfinite(ref).any()
    np.testing.assert_allclose(v[1], ref, rtol=0, atol=1e-10)
    assert np.isfinite(v[:, np.isfinite(ref).all(axis=1)]).all()  # no interval flagged


@pytest.mark.parametrize("which", ["decomposed", "compressed"])
def test_decomposed_and_compressed_sequences_are_exact(tmp_path, which):
    """A decomposed case (`processor*`, merged once) and gzip-compressed ASCII fields: the
    sequence's values at prepared points are the steady reader's cellPoint there."""
    import shutil

    src = DATA.parents[1] / "openfoam" / ("block_decomposed" if which == "decomposed"
                                          else "turbineSiting_cut_ascii")
    case = tmp_path / "case"
    shutil.copytree(src, case)
    t0 = "100" if which == "decomposed" else "168"
    dirs = sorted(case.glob("processor*")) if which == "decomposed" else [case]
    for d in dirs:
        shutil.copytree(d / t0, d / "200")
    of = lj.io.read_openfoam_field(case, time=t0)
    lo, hi = of.bounds[0].min(axis=0), of.bounds[1].max(axis=0)
    rng = np.random.default_rng(1)
    pts = lo + (0.2 + 0.6 * rng.random((40, 3))) * (hi - lo)
    seq = load_field_sequence(case, exact_at=pts, grid_fallback=False,
                              region=(lo + 0.2 * (hi - lo), lo + 0.8 * (hi - lo)))
    w = seq.window(0, 1)
    o = np.asarray(w.origin, np.float64) + np.asarray(w.origin_lo, np.float64)
    got = np.asarray(w.sample_local_at(jnp.asarray(pts - o), float(w.times[1])))
    ref = sample_openfoam(case, pts, time=t0)
    np.testing.assert_array_equal(np.isnan(got), np.isnan(ref))
    assert np.isfinite(ref).sum() > 30
    np.testing.assert_allclose(got[np.isfinite(ref)], ref[np.isfinite(ref)], rtol=0, atol=1e-10)


def test_exact_sequence_gradients_match_finite_differences_of_the_mesh():
    """d/d(vertex values) and d/d(position) of the exact sequence at a prepared point against
    central differences of the mesh's own cellPoint (the numpy sampler, moved points)."""
    from lidarjax.io.openfoam import read_openfoam_field

    # generic points (off the mesh's and the tets' planes, where cellPoint is smooth)
    pts = np.array([150.0, 60.0, 0.0]) + np.array([[3.3, 4.1, 7.7], [-6.2, 2.9, 13.1],
                                                   [1.7, -5.3, 21.4]])
    seq = load_field_sequence(DATA, exact_at=pts, region=(pts.min(0) - 5, pts.max(0) + 5),
                              time_range=(10.0, 12.0))
    w = seq.window(0, 1)
    o = np.asarray(w.origin, np.float64) + np.asarray(w.origin_lo, np.float64)
    q = jnp.asarray(pts[1] - o)
    t = 0.7 * float(w.times[1]) + 0.3 * float(w.times[0])
    s = (t - float(w.times[0])) / float(w.times[1] - w.times[0])
    jac = np.asarray(jax.jacfwd(lambda p: w.sample_local_at(p, t))(q))  # (3 out, 3 in)
    samplers = [read_openfoam_field(DATA, time=n).sampler() for n in ("10", "12")]
    eps = 1e-4
    fd = np.zeros((3, 3))
    for a in range(3):
        e = np.zeros(3)
        e[a] = eps
        v = [(1 - s) * samplers[0].sample_points(pts[1] + sgn * e)[0]
             + s * samplers[1].sample_points(pts[1] + sgn * e)[0] for sgn in (1, -1)]
        fd[:, a] = (v[0] - v[1]) / (2 * eps)
    np.testing.assert_allclose(jac, fd, rtol=1e-6, atol=1e-8)
    # vertex values: the mix is linear in them, weights (1 - s) lam and s lam
    gv = np.asarray(jax.grad(lambda v: eqx.tree_at(lambda f: f.values, w, v)
                             .sample_local_at(q, t)[0])(w.values))
    assert np.isclose(gv[0].sum(), 1 - s) and np.isclose(gv[1].sum(), s)
    vals = np.asarray(w.values)
    k = int(np.flatnonzero(np.abs(gv[0, :, :, 0]).sum(axis=1))[0])
    bump = np.zeros_like(vals)
    bump[0, k, :, 0] = 1e-3
    moved = eqx.tree_at(lambda f: f.values, w, jnp.asarray(vals + bump))
    lo_ = eqx.tree_at(lambda f: f.values, w, jnp.asarray(vals - bump))
    fd_v = (float(moved.sample_local_at(q, t)[0]) - float(lo_.sample_local_at(q, t)[0])) / 2e-3
    assert np.isclose(fd_v, gv[0, k, :, 0].sum(), rtol=1e-8)


def test_decomposed_sequence_missing_a_processors_time_is_flagged(tmp_path):
    """A decomposed case whose processor 2 lacks time 200: one warning line naming that
    processor's missing file, snapshot 200 NaN, snapshot 100 kept (exact)."""
    import shutil

    case = tmp_path / "case"
    shutil.copytree(DATA.parents[1] / "openfoam" / "block_decomposed", case)
    for d in sorted(case.glob("processor*")):
        if d.name != "processor2":
            shutil.copytree(d / "100", d / "200")
    of = lj.io.read_openfoam_field(case, time="100")
    lo, hi = of.bounds[0].min(axis=0), of.bounds[1].max(axis=0)
    pts = lo + np.array([[0.3, 0.4, 0.5], [0.6, 0.2, 0.7]]) * (hi - lo)
    seq = load_field_sequence(case, exact_at=pts, grid_fallback=False)
    with pytest.warns(UserWarning, match=r"processor2/200/U: missing") as caught:
        w = seq.window(0, 1)
    assert len(caught) == 1 and "\n" not in str(caught[0].message)
    o = np.asarray(w.origin, np.float64) + np.asarray(w.origin_lo, np.float64)
    q = jnp.asarray(pts - o)
    ref = sample_openfoam(case, pts, time="100")
    t0, t1 = (float(t) for t in w.times)
    np.testing.assert_allclose(np.asarray(w.sample_local_at(q, t0)), ref, atol=1e-10)
    assert np.isnan(np.asarray(w.sample_local_at(q, 0.5 * (t0 + t1)))).all()


def test_a_sequence_prepares_the_points_simulate_series_samples():
    """A tilted, turned Windcube V2 with the pulsed probe: the sequence prepared with
    `ExactPoints` (the node choice with the mount) holds exactly the points
    `simulate_series` samples, so with no graded grid behind them every LOS is answered
    (none NaN, none flagged). Here the choice with the mount (per height: fewer nodes
    where the beams see coarser cells) is not the mount-less one (the finest spacing's
    count everywhere): a series choosing without it would sample points not prepared."""
    from lidarjax.beam import ExactPoints

    scan, probe, h = lj.windcube_v2(), lj.PulsedProbe(), np.array([10.0, 20.0, 40.0])
    mount = lj.Mount([150.0, 60.0, 0.0], beta=30.0, pitch=3.0, roll=-2.0)
    points = ExactPoints(scan, mount, h, probe)
    seq = load_field_sequence(DATA, region=lj.scan_bounds(scan, mount, h, probe=probe),
                              exact_at=points, grid_fallback=False, time_range=(10.0, 16.0))
    w = seq.window(0, 1)
    chosen = lj.probe_for_field(w, scan, h, probe, mount=mount)
    assert isinstance(chosen, lj.beam.GradedProbe)  # nodes per height along the beams
    assert chosen.node_counts == points.probe.node_counts
    single = lj.probe_for_field(w, scan, h, probe).n_nodes  # without the mount
    assert chosen.node_counts != (single,) * h.size, (chosen.node_counts, single)
    o = np.asarray(w.origin, np.float64) + np.asarray(w.origin_lo, np.float64)
    local = (lj.io.simulate_points(scan, mount, h, chosen) - o).astype(w.dtype)
    np.testing.assert_array_equal(np.asarray(w.points_local), local)
    s = lj.simulate_series(seq, scan, mount, h, (10.0, 5.0), probe=probe)
    assert np.isfinite(np.asarray(s.los)).all() and not np.asarray(s.los_flags).any()


# ------------------------------------------------ right by default (issue 37, points 1, 3, 4)

GRADED = DATA.parents[1] / "openfoam_graded" / "case"
GRADED_LIDAR = np.array([100.0, 40.0, 0.0])
GRADED_HEIGHTS = np.array([5.0, 10.0, 20.0, 40.0, 60.0])


@pytest.fixture(scope="module")
def graded():
    """The committed ground-graded pimpleFoam run (first layer 0.99 m) flown through by a
    fixed Windcube V2 through the default call (no `exact_at`)."""
    scan, mount = lj.windcube_v2(), lj.Mount(GRADED_LIDAR)
    seq = load_field_sequence(GRADED, region=lj.scan_bounds(scan, mount, GRADED_HEIGHTS))
    s = lj.simulate_series(seq, scan, mount, GRADED_HEIGHTS, (10.0, 5.0))
    return seq, s


def test_graded_ground_run_is_exact_by_default(graded):
    """The default call agrees with OpenFOAM's own probes (interpolated between the snapshot
    times 10, 12.5, 15 s) within 1e-5 m/s at every height, 5 m next to the graded ground
    included: the graded grid it was sampled through before is 0.13 and 0.16 m/s off at 5
    and 10 m (tests/data/openfoam_graded/README.md)."""
    _, s = graded
    probes = read_openfoam_probes(GRADED / "postProcessing" / "lidarProbes")
    mp = lj.monitor_points(lj.windcube_v2(), lj.Mount(GRADED_LIDAR), GRADED_HEIGHTS)
    los, t_los = np.asarray(s.los), np.asarray(s.los_time)
    assert np.isfinite(los).all() and not np.asarray(s.los_flags).any()
    err = np.zeros(GRADED_HEIGHTS.size)
    for i, h in enumerate(GRADED_HEIGHTS):
        for b in range(5):
            ref = probe_los(probes, mp, h, b, t_los[:, i, b], lidar=GRADED_LIDAR,
                            snapshots=np.array([10.0, 12.5, 15.0]))
            err[i] = max(err[i], np.max(np.abs(los[:, i, b] - ref)))
    assert err.max() < 1e-5, err
    # the point sensors above the lidar are prepared points too: the probes' column there
    col = [int(np.flatnonzero((mp.height == h) & (mp.beam == -1))[0]) for h in GRADED_HEIGHTS]
    np.testing.assert_allclose(mp.points.reshape(-1, 3)[col][:, 2], GRADED_HEIGHTS)
    k = int(np.argmin(np.abs(probes.times - 10.0)))  # a snapshot's time: the sensors' first
    assert np.asarray(s.point_time)[0] == 10.0
    got = np.asarray(s.point_velocity)[0]
    ref = probes.values[k, col]  # speed and w: the same in the CFD and the north frame
    np.testing.assert_allclose(np.hypot(got[:, 0], got[:, 1]), np.hypot(ref[:, 0], ref[:, 1]),
                               rtol=0, atol=1e-5)
    np.testing.assert_allclose(got[:, 2], ref[:, 2], rtol=0, atol=1e-5)


def test_a_moving_lidar_through_a_mesh_sequence_warns_in_one_line(graded):
    """A moving lidar cannot be prepared: one UserWarning line naming the graded grid's local
    spacing above the lidar and the fix (here turned into an error, so nothing compiles).
    ``exact_at=False`` loads the graded grid only: nothing to make exact, nothing to say."""
    seq, _ = graded
    scan, mount = lj.windcube_v2(), lj.Mount(GRADED_LIDAR)
    motion = lj.SinusoidalMotion.of(roll=(2.0, 10.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        with pytest.raises(UserWarning) as caught:
            lj.simulate_series(seq, scan, mount, GRADED_HEIGHTS, (10.0, 5.0), motion=motion)
    msg = str(caught.value)
    assert "\n" not in msg and "moving lidar" in msg, msg
    # the graded grid's own spacing there (the mesh's first layer is 0.99 m)
    assert re.search(r"local spacing 0\.9\d* m at 5 m, [34]\.\d* m at 60 m above the lidar", msg), msg
    assert "finer `spacing`" in msg and "exact_at=False" in msg, msg
    plain = load_field_sequence(GRADED, exact_at=False)
    assert not plain.can_be_exact and plain.made_exact(np.zeros((1, 3))) is plain


def test_a_time_directory_without_u_is_named_and_flagged_within_time_range(tmp_path):
    """A time directory without `U` between others: one warning line naming it. Without
    `time_range` it is skipped (interpolated across, as said); within a `time_range` given
    its snapshot is NaN: the LOS of the intervals next to it NaN, flagged BEAM_OUTSIDE, the
    others exact (OpenFOAM's probes)."""
    case = _transient_copy(tmp_path, ("10", "12", "14", "16", "18"))
    (case / "14" / "U").unlink()
    (case / "14" / "p").write_text("")  # a time directory holding other fields only
    with pytest.warns(UserWarning) as caught:
        skipped = load_field_sequence(case)
    assert len(caught) == 1, [str(w.message) for w in caught]
    msg = str(caught[0].message)
    assert "\n" not in msg and "time 14 holds no `U`" in msg and "interpolates" in msg, msg
    np.testing.assert_array_equal(skipped.times, [10.0, 12.0, 16.0, 18.0])
    scan, mount = lj.windcube_v2(), lj.Mount([150.0, 60.0, 0.0])
    h = HEIGHTS[:2]
    with pytest.warns(UserWarning) as caught:
        seq = load_field_sequence(case, region=lj.scan_bounds(scan, mount, h), max_snapshots=4,
                                  time_range=(10.0, 18.0))
        s = lj.simulate_series(seq, scan, mount, h, (10.0, 12.0))
    msgs = [str(w.message) for w in caught]
    assert len(msgs) == 1 and "time 14 within `time_range` holds no `U`" in msgs[0], msgs
    np.testing.assert_array_equal(seq.times, [10.0, 12.0, 14.0, 16.0, 18.0])
    los, t, flags = np.asarray(s.los), np.asarray(s.los_time), np.asarray(s.los_flags)
    bad = (t > 12.0) & (t < 16.0)
    good = t <= 12.0
    assert bad.any() and good.any()
    assert np.isnan(los[bad]).all() and (flags[bad] & int(lj.Flag.BEAM_OUTSIDE)).all()
    assert np.isfinite(los[good]).all() and not flags[good].any()
    assert np.isfinite(los[(t >= 16.0) & (t <= 18.0)]).all()
    probes = read_openfoam_probes(DATA / "postProcessing" / "lidarProbes")
    err = _probe_errors_window(s, probes, lj.monitor_points(scan, mount, h), h, good)
    assert err < 1e-5, err


def test_nonfinite_exact_points_are_refused_before_the_mesh_is_read(monkeypatch):
    from lidarjax.io import snapshots

    def no_mesh(*_):
        raise AssertionError("the mesh was read")

    monkeypatch.setattr(snapshots, "read_openfoam_mesh", no_mesh)
    pts = np.array([[150.0, 60.0, 10.0], [np.nan, 60.0, 20.0]])
    with pytest.raises(ValueError, match=r"`exact_at`: 1 of 2 points are not finite \(first: "
                                         r"row 1\); give finite CFD metres") as err:
        load_field_sequence(DATA, exact_at=pts)
    assert "\n" not in str(err.value)
    with pytest.raises(ValueError, match="`exact_at` must give finite"):
        load_field_sequence(DATA, exact_at=np.zeros((0, 3)))


def test_a_mesh_loaded_without_points_is_exact_where_simulate_samples():
    """`load_field` of one snapshot without `exact_at`: `simulate` from one mount samples the
    mesh's own cellPoint (OpenFOAM's probes at 10 s within 1e-5 m/s at every height, 5 m
    next to the graded ground included); a moving lidar or a traced (vmapped) mount cannot
    be prepared: one warning line (once per field) and the grid; ``exact_at=False`` is the
    grid, silently."""
    scan, mount = lj.windcube_v2(), lj.Mount(GRADED_LIDAR)
    region = lj.scan_bounds(scan, mount, GRADED_HEIGHTS)
    f = lj.io.load_field(GRADED, time="10", region=region)
    probes = read_openfoam_probes(GRADED / "postProcessing" / "lidarProbes")
    mp = lj.monitor_points(scan, mount, GRADED_HEIGHTS)
    los = np.asarray(lj.simulate(f, scan, mount, GRADED_HEIGHTS).los)
    err = [max(abs(los[i, b] - probe_los(probes, mp, h, b, 10.0, lidar=GRADED_LIDAR,
                                          snapshots=np.array([10.0, 12.5])))
               for b in range(5)) for i, h in enumerate(GRADED_HEIGHTS)]
    assert max(err) < 1e-5, err
    motion = lj.SinusoidalMotion.of(roll=(2.0, 10.0))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the warning as an error: nothing compiles
        with pytest.raises(UserWarning) as caught:
            lj.simulate_series(f, scan, mount, GRADED_HEIGHTS, (0.0, 5.0), motion=motion)
    msg = str(caught.value)
    assert "\n" not in msg and msg.startswith("simulate_series: a moving lidar"), msg
    assert re.search(r"local spacing 0\.9\d* m at 5 m", msg) and "exact_at=False" in msg, msg
    two = lj.Mount(np.stack([GRADED_LIDAR, GRADED_LIDAR]))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a traced mount: the grid, the warning said once
        batch = np.asarray(jax.vmap(lambda m: lj.simulate(f, scan, m, GRADED_HEIGHTS).los)(two))
    assert np.abs(batch[0] - los).max() > 0.05  # the graded grid next to the ground
    grid = lj.io.load_field(GRADED, time="10", region=region, exact_at=False)
    assert lj.beam.exact_by_default(grid, scan, mount, GRADED_HEIGHTS, None, "simulate") is grid


def test_a_mesh_grid_freed_after_the_registry_is_gone_raises_nothing(monkeypatch):
    """At interpreter exit a grid `load_field` resampled from a mesh may outlive the module
    globals of `lidarjax.beam` (None by then): freeing it then must not print "Exception
    ignored in ... 'NoneType' object has no attribute 'pop'" (it did once the suite froze
    its heap at exit); the grid still leaves the registry."""
    from lidarjax import beam

    grid = lj.GridField(np.arange(3.0), np.arange(3.0), np.arange(3.0), np.zeros((3, 3, 3, 3)))
    beam.register_mesh_grid(grid, lambda points: None, "a mesh")
    registry, key = beam._MESH_GRIDS, id(grid)
    assert key in registry
    unraisable = []
    monkeypatch.setattr(sys, "unraisablehook", unraisable.append)
    monkeypatch.setattr(beam, "_MESH_GRIDS", None)  # what interpreter shutdown does
    del grid
    gc.collect()
    assert not unraisable, [u.exc_value for u in unraisable]
    assert key not in registry
