"""`lidarjax.sensitivity_report` from Python: the budgets of a settings.dat's lidar over its
platform rotations (GUM: root-sum-square of the contributions, Reynolds scaling of the
speed, one-to-one north offset), the same as `lidarjax.uncertainty` per rotation, and
`write_sensitivity_report`'s files."""

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import Settings, read_table_csv, save_field_npz, write_settings
from lidarjax.workflows.sensitivity_report import (
    SensitivityReport,
    sensitivity_report,
    write_sensitivity_report,
)

BETAS = (0.0, 180.0)
STD = {"epsilon": 0.5, "pitch": 0.2, "location": (0.05, 0.05, 0.1), "speed": 0.5}


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("sens_report")
    settings = Settings(zone=2, verbose=1, height=30.0, nh=3, gamma=5.0, beta=0.0, psi=180.0,
                        epsilon=10.0, betas=np.array(BETAS),
                        locations=np.array([[2.0, 1.0, 20.5], [-1.0, -2.0, 20.5]]))
    write_settings(root / "settings.dat", settings)
    x = np.linspace(-50, 50, 21)
    z = np.linspace(0, 60, 13)
    fields = {}
    for b in BETAS:
        f = lj.GridField.from_function(lj.scenes.hemisphere(20.0, 15.0, 90.0 + b).sample, x, x, z)
        fields[b] = root / f"platform_{int(b)}.npz"
        save_field_npz(fields[b], f)
    report = sensitivity_report(root / "settings.dat", fields, std=STD, pitch=0.4)
    return root, settings, fields, report


def test_budget_physics(case):
    _, _, _, report = case
    assert isinstance(report, SensitivityReport) and report.betas == BETAS
    b = report.budget
    assert report.outputs == ("lidar_speed", "lidar_direction", "cff_U", "cff_th")
    assert np.asarray(b.std["lidar_speed"]).shape == (2, 3)
    # uncorrelated inputs: u is the root-sum-square of the contributions |c_i| u_i
    for o in report.outputs:
        np.testing.assert_allclose(b.std[o], np.sqrt((b.contribution[o] ** 2).sum(-1)),
                                   rtol=1e-10)
    n = b.inputs.index
    # Reynolds scaling: the lidar's speed is proportional to the free stream (15 m/s)
    np.testing.assert_allclose(b.jacobian["lidar_speed"][..., n("speed")],
                               b.value["lidar_speed"] / 15.0, rtol=1e-10)
    # the reported direction turns one to one with the north offset
    np.testing.assert_allclose(b.jacobian["lidar_direction"][..., n("epsilon")], 1.0, rtol=1e-10)
    # z/H: the lidar's z plus the height over the lidars' mean z (20.5 m)
    assert report.ref_height == pytest.approx(20.5)
    np.testing.assert_allclose(report.z_over_h, (20.5 + np.array([[10.0, 20.0, 30.0]] * 2)) / 20.5)
    assert report.largest["lidar_speed"] == pytest.approx(float(np.nanmax(b.std["lidar_speed"])))


def test_one_batch_equals_uncertainty_per_rotation(case):
    _, settings, fields, report = case
    k = 1
    mount = lj.Mount(settings.location(BETAS[k]), beta=BETAS[k], gamma=5.0, psi=180.0,
                     epsilon=10.0, pitch=0.4)
    one = lj.uncertainty(lj.io.load_field(fields[BETAS[k]]), lj.windcube_v2(), mount,
                         [10.0, 20.0, 30.0], std=STD, u_ref=(-15.0, 0.0, 0.0),
                         outputs=("lidar_speed",))
    np.testing.assert_allclose(report.budget.std["lidar_speed"][k], np.asarray(one.std["lidar_speed"]),
                               rtol=1e-10)


def test_fields_as_sequence_function_or_loaded(case):
    root, settings, fields, report = case
    loaded = [lj.io.load_field(fields[b]) for b in BETAS]
    for given in (loaded, lambda b: fields[b]):
        again = sensitivity_report(settings, given, std={"epsilon": 0.5}, pitch=0.4,
                                   outputs=("lidar_direction",), ref_height=30.0)
        np.testing.assert_allclose(again.budget.value["lidar_direction"],
                                   report.budget.value["lidar_direction"], rtol=1e-12)
        assert again.ref_height == 30.0


def test_writer(case):
    root, _, _, report = case
    out = root / "out"
    written = write_sensitivity_report(out, report, plots=False,
                                       metadata={"settings": "settings.dat", "scan": "V2"})
    assert [p.name for p in written] == [f"budget_{o}.csv" for o in report.outputs]
    t = read_table_csv(out / "budget_lidar_speed.csv")
    np.testing.assert_allclose(t.columns["beta"], np.repeat(BETAS, 3))
    np.testing.assert_allclose(t.columns["u"], report.budget.std["lidar_speed"].reshape(-1),
                               rtol=1e-12)
    assert t.units["d_pitch"] == "m/s per deg"
    # the caller's metadata first (and winning), then the report's
    assert list(t.metadata)[:2] == ["settings", "scan"] and t.metadata["scan"] == "V2"
    assert t.metadata["std"].startswith("epsilon=0.5;pitch=0.2")
    assert "GUM" in t.metadata["method"]


def test_writer_figures(case):
    import matplotlib  # noqa: F401  (the test extra brings it)
    root, _, _, report = case
    names = [p.name for p in write_sensitivity_report(root / "figs", report)]
    assert names[-2:] == ["budget.png", "sensitivity_profiles.png"]


@pytest.mark.parametrize("kwargs, message", [
    ({"outputs": ("los",)}, "not per-height"),
    ({"n_monte_carlo": 1}, "n_monte_carlo must be 0 or at least 2"),
    ({"ref_height": -1.0}, "ref_height must be positive"),
    ({"pitch": float("nan")}, "pitch must be a finite angle"),
    ({"scan": "lidar9"}, "unknown scan"),
])
def test_errors(case, kwargs, message):
    _, settings, fields, _ = case
    with pytest.raises(ValueError, match=message):
        sensitivity_report(settings, fields, std={"epsilon": 0.5}, **kwargs)
