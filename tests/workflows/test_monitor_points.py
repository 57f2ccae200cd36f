"""CFD monitor points (`lidarjax.monitor_points`, `lidarjax.simulate_from_monitor_points`):
the lidar's points out (OpenFOAM, zCFD, CSV), the CFD code's samples back in,
and the same `Simulation` as `simulate` on the field itself."""

import re

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import (
    read_monitor_points_csv,
    read_monitor_values_csv,
    read_openfoam_probes,
    write_monitor_points_csv,
    write_openfoam_probes,
    write_zcfd_probes,
)

from .._foamwrite import write_probes_output
from ..helpers import DATA

SCENE = lj.scenes.hemisphere(radius=20.0, speed=10.0, direction=250.0)
SCAN = lj.windcube_v2()
HEIGHTS = np.array([20.0, 40.0, 60.0, 80.0])  # as the real case below: shared compilations
MOUNTS = [lj.Mount([4.0, 3.0, 20.1], beta=0.0, gamma=5.0, psi=180.0, epsilon=21.0),
          lj.Mount([-3.0, 6.0, 20.1], beta=30.0, gamma=5.0, psi=180.0, epsilon=21.0, pitch=2.0)]
U_REF = 10.0 * np.asarray(lj.heading(250.0))
OUTPUTS = ("los", "lidar_velocity", "point_velocity", "free_velocity", "cff_u", "cff_v", "cff_w",
           "cff_U", "cff_th", "cfp_u", "cfp_v", "cfp_w", "cfp_U", "cfp_th", "flags")


@pytest.fixture(scope="module")
def case():
    """The pulsed probe (the point probe goes through the same code with one node: the
    command-line test covers it)."""
    probe = lj.PulsedProbe()
    locs = lj.monitor_points(SCAN, MOUNTS, HEIGHTS, probe)
    values = np.asarray(SCENE.sample(locs.points))
    refs = [lj.simulate(SCENE, SCAN, m, HEIGHTS, probe=probe, u_ref=U_REF) for m in MOUNTS]
    return probe, locs, values, refs


def assert_same(sims, refs, atol=1e-12):
    for sim, ref in zip(sims, refs, strict=True):
        for k in OUTPUTS:
            np.testing.assert_allclose(np.asarray(getattr(sim, k)), np.asarray(getattr(ref, k)),
                                       rtol=0, atol=atol, err_msg=k)


def test_locations_are_named_weighted_and_where_simulate_looks(case):
    probe, locs, _, refs = case
    q = probe.n_nodes
    assert len(locs.labels) == 2 and locs.labels[0] == "b0"
    for label, ref in zip(locs.labels, refs, strict=True):
        rows = locs.rows(label)
        beams = rows[locs.beam[rows] >= 0]
        # weights of each (height, beam) sum to one; nodes behind the lidar are left out
        for h in HEIGHTS:
            for b in range(5):
                sel = beams[(locs.height[beams] == h) & (locs.beam[beams] == b)]
                assert 1 <= sel.size <= q
                np.testing.assert_allclose(locs.weight[sel].sum(), 1.0, atol=1e-12)
        # focus points are simulate's own
        focus_node = q // 2
        foc = beams[locs.node[beams] == focus_node]
        np.testing.assert_allclose(locs.points[foc].reshape(4, 5, 3), np.asarray(ref.points),
                                   atol=1e-12)
        point = rows[locs.beam[rows] == -1]
        np.testing.assert_allclose(locs.points[point][:, 2] - 20.1, HEIGHTS, atol=1e-12)
    assert all(re.fullmatch(r"b(0|30)_h\d+_(beam\d_q\d|point)", n) for n in locs.names)


def test_openfoam_round_trip_with_restart_equals_simulate(case, tmp_path):
    probe, locs, values, refs = case
    root = tmp_path / "postProcessing" / "lidarProbes"
    stale = values + 1.0
    # a run written at 0..200, restarted from 100 (the later folder wins at 100 and 200)
    write_probes_output(root / "0" / "U", locs, [(0, stale * 0), (100, stale), (200, stale)])
    write_probes_output(root / "100" / "U", locs, [(100, stale), (200, values)])
    samples = read_openfoam_probes(root)
    assert samples.start_times == ("0", "100") and samples.times.tolist() == [0, 100, 200]
    sims = lj.simulate_from_monitor_points(locs, samples.values_for(locs), SCAN, MOUNTS, HEIGHTS,
                                   probe=probe, u_ref=U_REF)
    assert_same(sims, refs)
    np.testing.assert_allclose(samples.values_for(locs, time=100), stale)
    np.testing.assert_allclose(samples.values_for(locs, window=(100, 200)), values + 0.5)


def test_csv_values_and_probe_list_round_trip(case, tmp_path):
    probe, locs, values, refs = case
    write_monitor_points_csv(tmp_path / "p.csv", locs, metadata={"scan": "windcube_v2"})
    back = read_monitor_points_csv(tmp_path / "p.csv")
    assert back.names == locs.names and back.mount == locs.mount
    np.testing.assert_array_equal(back.points, locs.points)  # repr: exact
    np.testing.assert_array_equal(back.beam, locs.beam)
    np.testing.assert_array_equal(back.node, locs.node)
    np.testing.assert_array_equal(np.isnan(back.weight), np.isnan(locs.weight))
    lines = ["# sampled by some CFD code", "Name,U [m/s],V [m/s],W [m/s],p"]
    order = np.random.default_rng(0).permutation(len(locs))  # any row order
    lines += [f"{locs.names[i]},{values[i, 0]:.17g},{values[i, 1]:.17g},{values[i, 2]:.17g},0" for i in order]
    (tmp_path / "v.csv").write_text("\n".join(lines) + "\n")
    sims = lj.simulate_from_monitor_points(back, read_monitor_values_csv(tmp_path / "v.csv"), SCAN, MOUNTS,
                                   HEIGHTS, probe=probe, u_ref=U_REF)
    assert_same(sims, refs)


def test_probes_outside_the_mesh_are_flagged_not_bridged(case, tmp_path):
    probe, locs, values, refs = case
    lost = int(np.flatnonzero((np.asarray(locs.mount) == "b30") & (locs.height == 40.0)
                              & (locs.beam == 2))[0])
    write_probes_output(tmp_path / "U", locs, [(1, values)], unset={lost})
    samples = read_openfoam_probes(tmp_path / "U")
    assert not samples.found[lost] and np.isnan(samples.values[0, lost]).all()
    sims = lj.simulate_from_monitor_points(locs, samples.values_for(locs), SCAN, MOUNTS, HEIGHTS,
                                   probe=probe, u_ref=U_REF)
    assert np.isnan(np.asarray(sims[1].los)[1, 2]) and np.isnan(np.asarray(sims[1].cff_U)[1])
    assert int(sims[1].flags[1]) & int(lj.Flag.BEAM_OUTSIDE)
    np.testing.assert_allclose(np.asarray(sims[1].los)[[0, 2, 3]], np.asarray(refs[1].los)[[0, 2, 3]],
                               atol=1e-12)
    assert_same(sims[:1], refs[:1])


def test_los_gradient_wrt_samples_is_the_probe_weight(case):
    probe, locs, values, _ = case
    rows = locs.rows("b0")
    field = lj.MonitorPointField(locs.points[rows], values[rows], origin=MOUNTS[0])

    def los(vel):
        f = lj.MonitorPointField.__new__(lj.MonitorPointField)
        for k, v in vars(field).items():
            object.__setattr__(f, k, v)
        object.__setattr__(f, "velocity", vel)
        return lj.simulate(f, SCAN, MOUNTS[0], HEIGHTS, probe=probe).los[1, 3]

    g = np.asarray(jax.jit(jax.grad(los))(field.velocity))  # one compiled gradient
    sel = (locs.height[rows] == 40.0) & (locs.beam[rows] == 3)
    direction = np.asarray(lj.simulate(SCENE, SCAN, MOUNTS[0], HEIGHTS).directions)[3]
    np.testing.assert_allclose(g[sel], locs.weight[rows][sel][:, None] * direction, atol=1e-12)
    assert np.all(g[~sel] == 0)


def test_writers_layouts(case, tmp_path):
    _, locs, _, _ = case
    foam = write_openfoam_probes(tmp_path / "lidarProbes", locs).read_text()
    assert re.search(r"^lidarProbes\n\{", foam, re.M)
    for key in ("type                probes;", 'libs                ("libsampling.so");',
                "interpolationScheme cellPoint;", "fields              (U);"):
        assert key in foam
    body = foam[foam.index("probeLocations"):]
    pts = re.findall(r"^\s+\(([-\d.e+]+) ([-\d.e+]+) ([-\d.e+]+)\)  // (\d+) (\S+)$", body, re.M)
    assert [p[4] for p in pts] == list(locs.names)
    np.testing.assert_array_equal(np.array([p[:3] for p in pts], float), locs.points)
    ns: dict = {}
    exec(write_zcfd_probes(tmp_path / "z.py", locs, frequency=50).read_text(), ns)
    report = ns["turb_probe"]["report"]
    assert report["frequency"] == 50 and len(report["monitor"]) == len(locs)
    mr = report["monitor"]["MR_1"]
    assert mr["name"] == locs.names[0] and mr["variables"] == ["V"]
    assert mr["point"] == locs.points[0].tolist()


def test_mismatched_configuration_is_refused(case, tmp_path):
    probe, locs, values, _ = case
    with pytest.raises(ValueError, match="not among the probes"):
        lj.simulate_from_monitor_points(locs, values, SCAN, MOUNTS, HEIGHTS + 1.0, probe=probe)
    moved = [MOUNTS[0], lj.Mount([-3.0, 6.5, 20.1], beta=30.0, gamma=5.0, psi=180.0,
                                 epsilon=21.0, pitch=2.0)]
    with pytest.raises(ValueError, match="was written at"):
        lj.simulate_from_monitor_points(locs, values, SCAN, moved, HEIGHTS, probe=probe)
    other = lj.monitor_points(SCAN, MOUNTS, HEIGHTS * 1.5, probe)
    write_probes_output(tmp_path / "U", other, [(1, np.zeros((len(other), 3)))])
    with pytest.raises(ValueError, match="other probes"):
        read_openfoam_probes(tmp_path / "U").values_for(locs)


REAL = DATA / "openfoam_probes" / "turbineSiting"


class GaussPulsedProbe(lj.AbstractProbe):
    """The pulsed weighting on the 9-node Gauss-Legendre rule the committed OpenFOAM output
    was sampled at (lidarjax before nodes followed the field's resolution; the weighting is
    `lj.PulsedProbe`'s): any `AbstractProbe` drives the monitor points and the forward model."""

    pulsed: lj.PulsedProbe = lj.PulsedProbe()

    def nodes(self, focus_range):
        x, w = np.polynomial.legendre.leggauss(9)
        x, w = 0.5 * (x - x[::-1]), 0.5 * (w + w[::-1])
        offsets = self.support() * jnp.asarray(x)
        weights = jnp.asarray(w / w.sum()) * self.weight(offsets)
        return offsets, weights / jnp.sum(weights)

    def weight(self, offset, focus_range=None):
        return self.pulsed.weight(offset)

    def support(self, focus_range=None):
        return self.pulsed.support(focus_range)

    def scaled(self, factor):
        return GaussPulsedProbe(self.pulsed.scaled(factor))

    @property
    def tail(self):
        return self.pulsed.tail


def test_real_openfoam_probes_output_reads_back_through_the_forward_model():
    """OpenFOAM v1912's own probes output (turbineSiting, see RECIPE.md) at the points of
    `lidarjax monitor-points`: the probe list is recovered exactly from the configuration, the header
    agrees to OpenFOAM's printed precision, and the LOS / reconstruction equal an independent
    numpy evaluation of the probe weights and the Windcube V2 formulas."""
    from lidarjax.io import read_settings
    from lidarjax.workflows.seed_tables import settings_mounts

    settings = read_settings(REAL / "settings.dat")
    mounts = settings_mounts(settings, [0.0, 90.0])
    heights = HEIGHTS
    probe = GaussPulsedProbe()
    locs = lj.monitor_points(SCAN, mounts, heights, probe)
    written = read_monitor_points_csv(REAL / "lidarProbes.csv")
    assert written.names == locs.names
    np.testing.assert_allclose(written.points, locs.points, rtol=0, atol=1e-9)
    samples = read_openfoam_probes(REAL / "postProcessing" / "lidarProbes")
    assert samples.times.tolist() == [168.0] and samples.found.all()
    values = samples.values_for(locs)
    assert np.isfinite(values).all() and 3.0 < np.linalg.norm(values, axis=1).min()
    sims = lj.simulate_from_monitor_points(locs, values, SCAN, mounts, heights, probe=probe,
                                   u_ref=[10.0, 0.0, 0.0])
    sim = sims[0]  # beta 0, gamma = psi = epsilon = 0: lidar frame = CFD frame
    rows = locs.rows("b0")
    directions = np.asarray(sim.directions)
    los = np.zeros((4, 5))
    for i in rows[locs.beam[rows] >= 0]:
        h = int(np.flatnonzero(heights == locs.height[i])[0])
        b = locs.beam[i]
        los[h, b] += locs.weight[i] * values[i] @ directions[b]
    np.testing.assert_allclose(np.asarray(sim.los), los, atol=1e-12)
    c = np.deg2rad(28.0)
    dbs = np.stack([(los[:, 1] - los[:, 3]) / (2 * np.sin(c)), (los[:, 0] - los[:, 2]) / (2 * np.sin(c)),
                    los[:, 4]], axis=1)
    np.testing.assert_allclose(np.asarray(sim.lidar_velocity), dbs, atol=1e-12)
    point = values[rows[locs.beam[rows] == -1]]
    np.testing.assert_allclose(np.asarray(sim.point_velocity), point, atol=1e-12)
    # the pulsed probe is cut at the lidar below about 41 m (the vertical beam): flagged only
    truncated = int(lj.Flag.PROBE_TRUNCATED)
    for s in sims:
        assert np.asarray(s.flags).tolist() == [truncated, truncated, 0, 0]
