"""`lidarjax sensitivity`: budgets for every beta of a settings.dat in one batch, CSV and
figures, and one-line errors for bad names and values."""

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.io import Settings, read_table_csv, save_field_npz, write_settings


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("sens_cli")
    betas = np.array([0.0, 120.0, 240.0])
    locs = np.array([[2.0, 1.0, 20.5], [1.0, -2.0, 20.5], [-2.0, 1.0, 20.5]])
    write_settings(root / "settings.dat", Settings(
        zone=2, verbose=1, height=30.0, nh=3, gamma=5.0, beta=0.0, psi=180.0, epsilon=10.0,
        betas=betas, locations=locs))
    x = np.linspace(-50, 50, 21)
    z = np.linspace(0, 60, 13)
    (root / "runs").mkdir()
    for b in betas:
        f = lj.GridField.from_function(lj.scenes.hemisphere(20.0, 15.0, 90.0 + b).sample, x, x, z)
        save_field_npz(root / "runs" / f"platform_{int(b)}.npz", f)
    return root


def test_budget_files_and_tables(case, capsys):
    out = case / "out"
    rc = main(["sensitivity", str(case / "settings.dat"), "--field",
               str(case / "runs" / "platform_{beta}.npz"), "--std", "epsilon=0.5",
               "--std", "pitch=0.2", "--std", "location=0.05,0.05,0.1", "--std", "speed=0.5",
               "--pitch", "0.4",
               "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert text.count("== beta =") == 3 and "lidar_speed [m/s]" in text
    t = read_table_csv(out / "budget_lidar_speed.csv")
    assert t.units["d_pitch"] == "m/s per deg" and t.units["u_z"] == "m/s"
    np.testing.assert_allclose(t.columns["beta"], np.repeat([0.0, 120.0, 240.0], 3))
    np.testing.assert_allclose(t.columns["z/H"][:3], (20.5 + np.array([10.0, 20.0, 30.0])) / 20.5)
    # uncorrelated inputs: u is the root-sum-square of the contributions, each |d| * u_i
    parts = np.stack([t.columns[f"u_{n}"] for n in ("epsilon", "pitch", "x", "y", "z", "speed")])
    np.testing.assert_allclose(t.columns["u"], np.sqrt((parts**2).sum(0)), rtol=1e-10)
    np.testing.assert_allclose(t.columns["u_z"], np.abs(t.columns["d_z"]) * 0.1, rtol=1e-12)
    # Reynolds scaling of the CFD runs: the lidar's speed is proportional to the free stream
    np.testing.assert_allclose(t.columns["d_speed"], t.columns["lidar_speed"] / 15.0, rtol=1e-12)
    # the reported direction turns one to one with the north offset
    d = read_table_csv(out / "budget_lidar_direction.csv")
    np.testing.assert_allclose(d.columns["d_epsilon"], 1.0, rtol=1e-10)
    assert (out / "budget.png").is_file() and (out / "sensitivity_profiles.png").is_file()
    # one batch over the betas gives what the API gives for one beta alone
    sim_mount = lj.Mount([1.0, -2.0, 20.5], beta=120.0, gamma=5.0, psi=180.0, epsilon=10.0,
                         pitch=0.4)
    field = lj.io.load_field(case / "runs" / "platform_120.npz")
    b = lj.uncertainty(field, lj.windcube_v2(), sim_mount, [10.0, 20.0, 30.0],
                       std={"epsilon": 0.5, "pitch": 0.2, "location": (0.05, 0.05, 0.1),
                            "speed": 0.5},
                       u_ref=(-15.0, 0.0, 0.0), outputs=("lidar_speed",))
    np.testing.assert_allclose(t.columns["u"][3:6], np.asarray(b.std["lidar_speed"]), rtol=1e-10)
    for n in ("pitch", "z", "speed"):
        np.testing.assert_allclose(t.columns[f"d_{n}"][3:6],
                                   np.asarray(b.jacobian["lidar_speed"])[:, b.inputs.index(n)],
                                   rtol=1e-10, atol=1e-14)


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--std", "tilt=0.5"], "unknown input 'tilt'"),
        (["--std", "pitch=abc"], "'abc' is not a number"),
        (["--std", "pitch=-1"], "finite and >= 0"),
        (["--std", "pitch"], "expected NAME=VALUE"),
        (["--std", "location=1,2"], "1 or 3 values"),
        (["--std", "direction=2"], "unknown input 'direction'"),
        ([], "at least one --std"),
        (["--std", "pitch=1", "--outputs", "lidar_speed,speed"], "--outputs"),
        (["--std", "pitch=1", "--n-monte-carlo", "1"], "--n-monte-carlo"),
    ],
)
def test_bad_input_exits_2_with_one_line(case, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(case)
    rc = main(["sensitivity", "settings.dat", "--field", "runs/platform_{beta}.npz"] + argv)
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lidarjax sensitivity: error:") and message in err
    assert len(err.splitlines()) == 1
