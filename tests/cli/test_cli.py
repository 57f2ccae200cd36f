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


@pytest.fixture(scope="module")
def table_path(seed_case):
    path = seed_case / "table.npz"
    assert main(["table", str(seed_case / "settings.dat"), "--field",
                 str(seed_case / "runs" / "platform_{beta}.npz"), "--scan", "windcube_v2",
                 "--out", str(path)]) == 0
    return path


def test_table_file_round_trip(table_path):
    table, meta = lj.io.load_table(table_path, return_metadata=True)
    assert (table.n_directions, table.n_heights, table.n_beams) == (4, 3, 5)
    assert meta["scan"] == "windcube_v2" and meta["psi_deg"] == 180.0
    np.testing.assert_allclose(table.heights, [10.0, 20.0, 30.0])
    # directions: CFD free stream (-15, 0, 0) seen through psi = 180, gamma = 5, epsilon = 21
    np.testing.assert_allclose(np.sort(np.asarray(table.directions)), [26.0, 116.0, 206.0, 296.0],
                               atol=1e-9)


def test_correct_sta_recovers_exact_model_records(seed_case, table_path):
    table = lj.io.load_table(table_path)
    rng = np.random.default_rng(5)
    n = 40
    truth_u, truth_d = rng.uniform(2.0, 25.0, n), rng.uniform(0.0, 360.0, n)
    rep = truth_u[:, None, None] * np.asarray(table.reconstructed_at(truth_d))  # (r, h, 3)
    time = np.datetime64("2024-03-01T00:10") + np.arange(n) * np.timedelta64(10, "m")
    heights = np.array([5.0, 10.0, 20.0, 30.0, 40.0])  # the record has more heights
    speed = np.full((n, 5), 7.0)
    direction = np.full((n, 5), 90.0)
    speed[:, 1:4] = np.hypot(rep[..., 0], rep[..., 1])
    direction[:, 1:4] = lj.wind_direction(rep)
    speed[3, 2] = np.nan  # a missing value stays a NaN record, nothing else changes
    lj.io.write_sta(seed_case / "rec.sta", time, heights, speed, direction, scan_angle=28.0,
                    direction_offset=21.0)  # the table's epsilon: beam 0 points there
    out = seed_case / "rec_corrected.csv"
    assert main(["correct", "--table", str(table_path), "--records",
                 str(seed_case / "rec.sta"), "--out", str(out), "--quiet"]) == 0
    rows = [line.split(",") for line in out.read_text().splitlines() if not line.startswith("#")]
    body = np.array(rows[1:])
    assert body.shape == (n * 3, 13)
    got = body[:, 2].astype(float).reshape(n, 3)
    got_d = body[:, 3].astype(float).reshape(n, 3)
    ok = np.ones((n, 3), bool)
    ok[3, 1] = False
    assert np.isnan(got[3, 1]) and body[3 * 3 + 1, 6] == "False"
    # .sta values carry 4 decimals: recovered to that precision
    np.testing.assert_allclose(got[ok], np.broadcast_to(truth_u[:, None], (n, 3))[ok], atol=2e-3)
    dd = (got_d - truth_d[:, None] + 180) % 360 - 180
    assert np.max(np.abs(dd[ok])) < 0.05


def test_correct_rtd_uses_raw_beams(seed_case, table_path):
    table = lj.io.load_table(table_path)
    truth_u, truth_d = 9.0, 200.0
    los = truth_u * np.asarray(table.response_at(truth_d))  # (h, b): beams 0, 90, 180, 270, V
    header = ["ScanAngle (\u00b0)=28", "DirectionOffset (\u00b0)=21",
              "Altitudes (m)=\t10\t20\t30", "********************"]
    cols = ["Timestamp", "Position"] + [f"{h}m Radial Wind Speed (m/s)" for h in (10, 20, 30)]
    rows = []
    for k, pos in enumerate(["0", "90", "180", "270", "V"]):
        rws = [f"{-los[j, k]:.6f}" for j in range(3)]  # .rtd: positive towards the lidar
        rows.append("\t".join([f"2024/03/01 00:0{k + 1}:00.00", pos, *rws]))
    text = "\n".join([f"HeaderSize={len(header)}", *header, "\t".join(cols), *rows]) + "\n"
    path = seed_case / "rec.rtd"
    path.write_bytes(text.encode("cp1252"))
    # five samples in ten minutes is far below the 80 % availability minimum: lift it, the
    # point here is the raw-beam inversion
    assert main(["correct", "--table", str(table_path), "--records", str(path), "--quiet",
                 "--min-availability", "0"]) == 0
    body = [line.split(",") for line in (seed_case / "rec_corrected.csv").read_text().splitlines()
            if not line.startswith(("#", "time"))]
    assert len(body) == 3
    np.testing.assert_allclose([float(r[2]) for r in body], truth_u, atol=1e-4)
    np.testing.assert_allclose([float(r[3]) for r in body], truth_d, atol=1e-3)


def test_correct_rejects_mismatched_heights(seed_case, table_path, capsys):
    time = np.array(["2024-03-01T00:10"], dtype="datetime64[m]")
    lj.io.write_sta(seed_case / "bad.sta", time, [40.0, 60.0], np.ones((1, 2)), np.ones((1, 2)),
                    direction_offset=21.0)
    assert main(["correct", "--table", str(table_path), "--records",
                 str(seed_case / "bad.sta"), "--quiet"]) == 2
    assert "heights" in capsys.readouterr().err


def test_dask_workers_start_when_the_default_dashboard_port_is_taken():
    """``--workers`` builds a local cluster; Dask's default HTTP port 8787 held by another
    process (another cluster, a notebook's dashboard) must not stop it (CI failure, stop 27)."""
    import socket
    from types import SimpleNamespace

    import distributed  # noqa: F401  (the test extra brings it)

    from lidarjax.cli._dask import dask_client

    held = socket.socket()
    try:
        try:
            held.bind(("0.0.0.0", 8787))
            held.listen()
        except OSError:
            pass  # already held by someone else: the case under test all the same
        with dask_client(SimpleNamespace(workers=1, scheduler=None, x64=True)) as client:
            assert client.submit(pow, 3, 2).result() == 9
    finally:
        held.close()
