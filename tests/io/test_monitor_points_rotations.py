"""`lidarjax monitor-points --field CASE --all` on platform rotations whose beams see other
cells, so that `lidarjax simulate` gives each rotation other node counts per height (issue
31, point 3): the roof lidar of `windAroundBuildings` (tests/data/openfoam/README.md,
`pulsed/roof12.dat`) at betas 0 and 30 deg. Every rotation's written nodes are the points
`simulate` prepares and samples for that rotation, and `--sampled` checks each rotation's.
"""

from __future__ import annotations

import contextlib
import io

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.io import read_monitor_points_csv, read_settings, simulate_points
from lidarjax.workflows.seed_tables import ExactPoints, settings_mounts, table_region

from ..helpers import DATA

FOAM = DATA / "openfoam"
CASE = FOAM / "windAroundBuildings_cut"
BETAS = (0.0, 30.0)
COMMON = ["--scan", "windcube_v2", "--probe", "pulsed"]


def _run(args):
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = main(args)
    return rc, out.getvalue(), err.getvalue()


@pytest.fixture(scope="module")
def roof(tmp_path_factory):
    """The settings (roof12's rows of BETAS), one run per beta (the same cut linked), the
    exact fields `lidarjax simulate` reads for each beta (the region it reads, made exact at
    the points it prepares) and what `monitor-points --field --all` wrote."""
    tmp = tmp_path_factory.mktemp("rot")
    lines = (FOAM / "pulsed" / "roof12.dat").read_text().splitlines()
    rows = [ln for ln in lines[2:] if ln.strip() and float(ln.split()[0]) in BETAS]
    settings = tmp / "roof2.dat"
    head = lines[1].split()
    head[3] = "2"  # heights 10 and 20 m: each rotation two node counts (ample, and quick)
    settings.write_text("\n".join([lines[0], "\t".join(head)] + rows) + "\n")
    for b in BETAS:
        (tmp / f"roof_{b:g}").symlink_to(CASE, target_is_directory=True)
    runs = str(tmp / "roof_{beta}")
    rc, _, err = _run(["monitor-points", str(settings), "--all", *COMMON, "--field", runs,
                       "--out", str(tmp / "w")])
    assert rc == 0, err
    s = read_settings(settings)
    scan, h = lj.windcube_v2(), np.asarray(s.heights())
    exact = {}
    for b, m in zip(BETAS, settings_mounts(s, BETAS), strict=True):
        at = ExactPoints(scan, m, h, lj.PulsedProbe())
        f = lj.io.load_field(CASE, region=table_region(s, [b], scan, probe=lj.PulsedProbe()),
                             exact_at=at)
        exact[b] = (m, f, at.probe)
    return settings, runs, scan, h, exact, read_monitor_points_csv(tmp / "w" / "lidarProbes.csv"), err


def test_each_rotation_writes_the_nodes_simulate_samples(roof):
    """The two rotations get different node counts per height; each rotation's written
    nodes are `simulate_points` of the probe simulate chooses for it (the exact sampler's
    prepared points: simulate matches every one of its queries there), ahead of the lidar."""
    _, _, scan, h, exact, locs, err = roof
    counts = {b: p.node_counts for b, (_, _, p) in exact.items()}
    assert counts[0.0] != counts[30.0], counts
    assert "beta 0: " + "/".join(map(str, counts[0.0])) in err
    assert "beta 30: " + "/".join(map(str, counts[30.0])) in err
    for b, (m, f, used) in exact.items():
        # simulate itself chooses the probe the exact field was prepared for
        again = lj.probe_for_field(f, scan, h, lj.PulsedProbe(), mount=m)
        assert again.node_counts == used.node_counts
        prepared = simulate_points(scan, m, h, used)
        np.testing.assert_allclose(
            np.asarray(f.index.points) + np.asarray(f.origin, np.float64)
            + np.asarray(f.origin_lo, np.float64), prepared, rtol=0, atol=1e-9)
        # the layout of simulate_points: the foci (h, b), the column (h), the nodes (h, b, q)
        nb = 5
        focus = prepared[:h.size * nb].reshape(h.size, nb, 3)
        nodes = prepared[h.size * (nb + 1):].reshape(h.size, nb, -1, 3)
        loc = np.asarray(m.location, np.float64)
        r = np.linalg.norm(focus - loc, axis=-1)  # (h, b) focus ranges
        along = np.einsum("hbqc,hbc->hbq", nodes - loc, (focus - loc) / r[..., None])
        ahead = np.abs(along - r[..., None]) < r[..., None]  # simulate's cut at the lidar
        rows = locs.rows(f"b{b:g}")
        rows = rows[locs.node[rows] >= 0]
        for i, hi in enumerate(h):
            for beam in range(nb):
                sel = rows[(locs.height[rows] == hi) & (locs.beam[rows] == beam)]
                q = locs.node[sel]
                # every node simulate samples ahead of the lidar, at its place, in order
                np.testing.assert_array_equal(q, np.flatnonzero(ahead[i, beam]))
                np.testing.assert_allclose(locs.points[sel], nodes[i, beam, q], rtol=0,
                                           atol=1e-9)
                # the height's own count carries the weight; the padding (at the focus) none
                w = locs.weight[sel]
                assert np.all(w[q < used.node_counts[i]] > 0)
                assert np.all(w[q >= used.node_counts[i]] == 0)
                np.testing.assert_allclose(nodes[i, beam, used.node_counts[i]:],
                                           np.broadcast_to(focus[i, beam], nodes[i, beam,
                                           used.node_counts[i]:].shape), rtol=0, atol=1e-9)


def test_sampled_checks_each_rotation_and_equals_simulate(roof, tmp_path):
    """`--sampled` of the CFD code's values at the written points (here the mesh's own
    cellPoint, as OpenFOAM's probes sample it) gives simulate's result for every rotation;
    samples of other nodes are refused in one line naming each rotation's counts."""
    settings, runs, scan, h, exact, locs, _ = roof
    values = np.full((len(locs), 3), np.nan)
    for b, (_, f, _) in exact.items():
        rows = locs.rows(f"b{b:g}")
        values[rows] = np.asarray(f.sample(locs.points[rows]))
    csv = tmp_path / "sampled.csv"
    csv.write_text("name,u,v,w\n" + "\n".join(
        f"{n},{u!r},{v!r},{w!r}" for n, (u, v, w) in zip(locs.names, values.tolist(), strict=True)))
    rc, _, err = _run(["monitor-points", str(settings), "--all", *COMMON, "--field", runs,
                       "--sampled", str(csv), "--out", str(tmp_path / "r")])
    assert rc == 0, err
    for b, (m, f, _) in exact.items():
        sim = lj.simulate(f, scan, m, h, probe=lj.PulsedProbe())
        got = lj.io.read_table_csv(tmp_path / "r" / f"simulation_{b:g}.csv").columns
        want = np.asarray(sim.lidar_speed)
        ok = np.isfinite(want)
        assert ok.all(), b
        np.testing.assert_array_equal(np.isnan(np.asarray(got["U_mag_lidar"])), ~ok)
        np.testing.assert_allclose(np.asarray(got["U_mag_lidar"])[ok], want[ok], rtol=0,
                                   atol=1e-9, err_msg=f"beta {b:g}")
    # samples missing beta 30's nodes at its top height (written for fewer nodes there):
    # refused in one line naming each rotation's node counts and what the file holds
    keep = ~((np.asarray(locs.mount) == "b30") & (locs.height == h[-1]) & (locs.node >= 0))
    csv.write_text("name,u,v,w\n" + "\n".join(f"{n},1,0,0" for n, k in
                                               zip(locs.names, keep, strict=True) if k))
    rc, _, err = _run(["monitor-points", str(settings), "--all", *COMMON, "--field", runs,
                       "--sampled", str(csv), "--out", str(tmp_path / "x")])
    assert rc == 2
    line = err.strip().splitlines()[-1]
    n30 = int((~keep).sum())
    assert "beta 0: " in line and "all held" in line, line
    assert f"{len(locs.rows('b30')) - n30} held there" in line, line
    for b, (_, _, p) in exact.items():
        assert f"beta {b:g}: " in line and "/".join(map(str, p.node_counts)) in line, line
