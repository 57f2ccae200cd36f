"""The command line: the seed workflow end to end, and clean failures on bad input."""

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.io import Settings, read_seed_output, read_table_csv, save_field_npz, write_settings


@pytest.fixture(scope="module")
def seed_case(tmp_path_factory):
    """A settings.dat over 4 betas with hemisphere 'platform' runs on one small grid."""
    root = tmp_path_factory.mktemp("seedcase")
    betas = np.array([0.0, 90.0, 180.0, 270.0])
    locs = np.tile([2.0, 1.0, 20.5], (4, 1))
    write_settings(root / "settings.dat", Settings(
        zone=2, verbose=1, height=30.0, nh=3, gamma=5.0, beta=90.0, psi=180.0, epsilon=21.0,
        betas=betas, locations=locs))
    x = np.linspace(-50, 50, 21)
    z = np.linspace(0, 60, 13)
    (root / "runs").mkdir()
    for b in betas:
        f = lj.GridField.from_function(lj.scenes.hemisphere(20.0, 15.0, 90.0).sample, x, x, z)
        save_field_npz(root / "runs" / f"platform_{int(b)}.npz", f)
    return root


def test_simulate_writes_seed_and_csv_files(seed_case, capsys):
    out = seed_case / "out"
    rc = main(["simulate", str(seed_case / "settings.dat"), "--field",
               str(seed_case / "runs" / "platform_{beta}.npz"), "--all", "--out", str(out)])
    assert rc == 0
    cols = read_seed_output(out / "windcube simulation 90 degrees.dat")
    np.testing.assert_allclose(cols["h"], [10.0, 20.0, 30.0])
    # seed convention: the free stream's azimuth is beta + gamma + epsilon, so
    # Th_lidar + cff_th == beta + gamma + epsilon
    np.testing.assert_allclose((cols["Th_lidar"] + cols["cff_th"]) % 360, 116.0, atol=2e-3)
    table = read_table_csv(out / "simulation_90.csv")
    assert table.units["Th_lidar"] == "deg, seed azimuth"
    assert "simulate" not in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--beta", "45"], "45"),
        (["--field", "nowhere_{beta}.npz"], "not found"),
        (["--all", "--field", "runs/platform_0.npz"], "{beta}"),
    ],
)
def test_simulate_bad_input_exits_nonzero_with_reason(seed_case, capsys, monkeypatch, argv, message):
    monkeypatch.chdir(seed_case)
    base = ["simulate", "settings.dat", "--field", "runs/platform_{beta}.npz"]
    args = base + argv
    if "--field" in argv:
        args = ["simulate", "settings.dat"] + argv
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("lidarjax simulate: error:") and message in err
    assert len(err.splitlines()) == 1
