"""The command line of issue 21: `table --param` (a table over directions x a profile
parameter), `correct --joint`, and `calibrate`, on small synthetic cases and the real
Windcube .rtd."""

import json

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.io import Settings, save_field_npz, write_settings

from ..helpers import windcube_folder

ALPHAS = (0.0, 0.2)
Z_REF = 20.0


LIDAR_Z = 20.5  # the lidar on top of the hemisphere; heights are measured from it


class _ShearedHemisphere:
    """The hemisphere 'platform' in a power-law inflow of the height above the lidar: a
    CFD-like run of one alpha."""

    def __init__(self, alpha):
        self.alpha, self.scene = alpha, lj.scenes.hemisphere(20.0, 15.0, 90.0)

    def __call__(self, p):
        z = np.maximum(np.asarray(p)[..., 2] - LIDAR_Z, 1e-3)
        return self.scene.sample(p) * ((z / Z_REF) ** self.alpha)[..., None]


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("profilecase")
    betas = np.arange(0.0, 360.0, 45.0)
    write_settings(root / "settings.dat", Settings(
        zone=2, verbose=1, height=30.0, nh=3, gamma=5.0, beta=90.0, psi=180.0, epsilon=21.0,
        betas=betas, locations=np.tile([2.0, 1.0, LIDAR_Z], (betas.size, 1))))
    x, z = np.linspace(-50, 50, 21), np.linspace(0, 60, 13)
    (root / "runs").mkdir()
    for a in ALPHAS:
        for b in betas:
            f = lj.GridField.from_function(_ShearedHemisphere(a), x, x, z)
            save_field_npz(root / "runs" / f"d{b:g}_a{a:g}.npz", f)
    field = str(root / "runs" / "d{beta}_a{alpha}.npz")
    assert main(["table", str(root / "settings.dat"), "--field", field, "--param",
                 "alpha=0,0.2", "--reference-height", str(Z_REF),
                 "--out", str(root / "profile.npz")]) == 0
    assert main(["table", str(root / "settings.dat"), "--field",
                 str(root / "runs" / "d{beta}_a0.npz"), "--out", str(root / "plain.npz")]) == 0
    return root


def _write_rtd(path, los, heights, eps=21.0):
    """A Windcube .rtd with one scan (5 rows, beams 0/90/180/270/V) per 10-minute record;
    `los` ``(r, h, 5)`` positive away from the lidar (the file stores the opposite)."""
    header = ["ScanAngle (\u00b0)=28", f"DirectionOffset (\u00b0)={eps:g}",
              "Altitudes (m)=\t" + "\t".join(f"{h:g}" for h in heights), "****"]
    cols = ["Timestamp", "Position"] + [f"{h:g}m Radial Wind Speed (m/s)" for h in heights]
    rows = []
    t0 = np.datetime64("2024-03-01T00:00:00")
    for i in range(los.shape[0]):
        for k, pos in enumerate(["0", "90", "180", "270", "V"]):
            t = (t0 + np.timedelta64(600 * i + 60 * (k + 1), "s")).astype(object)
            stamp = t.strftime("%Y/%m/%d %H:%M:%S.00")
            rows.append("\t".join([stamp, pos] + [f"{-los[i, j, k]:.6f}"
                                                  for j in range(los.shape[1])]))
    text = "\n".join([f"HeaderSize={len(header)}", *header, "\t".join(cols), *rows]) + "\n"
    path.write_bytes(text.encode("cp1252"))
    return t0 + np.timedelta64(600, "s") * (np.arange(los.shape[0]) + 1)


def test_table_param_builds_a_profile_table(case):
    table, meta = lj.io.load_table(case / "profile.npz", return_metadata=True)
    assert isinstance(table, lj.ProfileTable) and table.name == "alpha"
    np.testing.assert_allclose(table.parameters, ALPHAS)
    assert meta["profile"] == {"kind": "power_law", "reference_height_m": Z_REF}
    plain = lj.io.load_table(case / "plain.npz")
    # alpha = 0 is the plain table; the sheared run, whose velocities are the plain run's
    # times (z / z_ref)**alpha at the beam points, is the same per unit local speed (up to
    # the grid's linear interpolation of the power law: 5 m cells), where per unit reference
    # speed it differed by (z / z_ref)**0.2 = 0.87 to 1.08
    np.testing.assert_allclose(table.tables[0].response, plain.response, atol=1e-12)
    np.testing.assert_allclose(table.tables[1].response, plain.response, atol=2e-3)


def test_table_param_refuses_a_pattern_without_the_name(case, capsys):
    assert main(["table", str(case / "settings.dat"), "--field",
                 str(case / "runs" / "d{beta}_a0.npz"), "--param", "alpha=0,0.2",
                 "--reference-height", "20", "--out", str(case / "x.npz")]) == 2
    err = capsys.readouterr().err.strip()
    assert "{alpha}" in err and len(err.splitlines()) == 1


def test_correct_joint_recovers_records_and_falls_back_without_profile_axis(case, capsys):
    table = lj.io.load_table(case / "profile.npz")
    rng = np.random.default_rng(4)
    n = 12
    u, d, a = rng.uniform(5, 12, n), rng.uniform(0, 360, n), rng.uniform(0.03, 0.17, n)
    h = np.asarray(table.heights)
    los = (u[:, None, None] * ((h / Z_REF)[None, :] ** a[:, None])[..., None]
           * np.asarray(table.response_at(d, a)))
    _write_rtd(case / "j.rtd", los, h)
    out = case / "j.csv"
    assert main(["correct", "--table", str(case / "profile.npz"), "--records",
                 str(case / "j.rtd"), "--joint", "--min-availability", "0", "--quiet",
                 "--out", str(out)]) == 0
    assert out.with_suffix(".nc").is_file()
    body = [r.split(",") for r in out.read_text().splitlines() if not r.startswith(("#", "time"))]
    speeds = np.array([float(r[2]) for r in body]).reshape(n, -1)  # per record and height
    np.testing.assert_allclose(speeds, u[:, None] * (h / Z_REF)[None, :] ** a[:, None],
                               rtol=1e-4)
    rows = [r.split(",") for r in (case / "j_profile.csv").read_text().splitlines()
            if not r.startswith(("#", "time"))]
    got = np.array([[float(r[1]), float(r[2]), float(r[3])] for r in rows])
    np.testing.assert_allclose(got[:, 0], u, rtol=1e-4)
    np.testing.assert_allclose((got[:, 1] - d + 180) % 360 - 180, 0.0, atol=1e-3)
    np.testing.assert_allclose(got[:, 2], a, atol=1e-4)
    capsys.readouterr()
    # a table without a profile axis: one line says so, the records are corrected per height
    assert main(["correct", "--table", str(case / "plain.npz"), "--records",
                 str(case / "j.rtd"), "--joint", "--min-availability", "0", "--quiet",
                 "--out", str(case / "k.csv"), "--no-netcdf"]) == 0
    err = capsys.readouterr().err
    assert "no profile axis" in err and "per height" in err
    assert (case / "k.csv").is_file() and not (case / "k_profile.csv").exists()
    # a profile table without --joint is refused in one line
    assert main(["correct", "--table", str(case / "profile.npz"), "--records",
                 str(case / "j.rtd"), "--min-availability", "0", "--quiet",
                 "--out", str(case / "m.csv")]) == 2
    assert "--joint" in capsys.readouterr().err


def test_calibrate_cli_finds_a_north_offset_with_a_reference(case, capsys):
    table = lj.io.load_table(case / "plain.npz")
    rng = np.random.default_rng(8)
    n, de = 60, 2.5
    h = np.asarray(table.heights)
    u, d = rng.uniform(5, 12, n), rng.uniform(0, 360, n)
    # the instrument's north is off by de with the platform it stands on (the flow turns
    # with it, --north-offset site): the table sees every direction at d - de
    los = u[:, None, None] * np.asarray(table.response_at(d - de))
    los = los + 0.02 * rng.standard_normal(los.shape)
    times = _write_rtd(case / "c.rtd", los, h)
    lines = ["time,height_m,speed_m_s,direction_deg"]
    for i, t in enumerate(times):
        lines += [f"{t},{z:g},{u[i]:.4f},{d[i]:.4f}" for z in h]
    (case / "ref.csv").write_text("\n".join(lines) + "\n")
    out = case / "cal.json"
    assert main(["calibrate", "--table", str(case / "plain.npz"), "--records",
                 str(case / "c.rtd"), "--reference", str(case / "ref.csv"), "--wrt", "epsilon",
                 "--north-offset", "site", "--min-availability", "0", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["names"] == ["epsilon"] and doc["n_records"] == n and doc["flags"] == 0
    # `lidarjax table` wrote the velocity gradient along the beams: no warning, the model's
    # order stated
    assert lj.io.load_table(case / "plain.npz").beam_gradient is not None
    assert any("beam_gradient" in x and "first order" in x for x in doc["notes"])
    assert abs(doc["offset_deg"][0] - de) < 3 * doc["std_deg"][0] + 1e-3
    assert doc["std_deg"][0] < 0.2
    np.testing.assert_allclose(doc["value_deg"][0], 21.0 + doc["offset_deg"][0])
    capsys.readouterr()
    assert main(["calibrate", "--table", str(case / "plain.npz"), "--records",
                 str(case / "c.rtd"), "--min-availability", "0"]) == 0
    assert "epsilon (north offset) is not identifiable without a reference" in \
        capsys.readouterr().out


@pytest.mark.skipif(windcube_folder() is None, reason="../shared/data/windcube is absent")
def test_calibrate_cli_on_the_real_rtd_reports_against_the_header(tmp_path, capsys):
    path = windcube_folder() / "WLS866-104_2024_08_02__23_44_55.rtd"
    rec = lj.load_records(path, min_availability=0)
    scan = lj.windcube_v2(28.0)
    mount = lj.Mount([0.0, 0.0, 0.0])
    fields = [lj.scenes.uniform(10.0, d) for d in range(0, 360, 30)]
    sims = [lj.simulate(f, scan, mount, rec.heights, u_ref=10.0 * np.asarray(lj.heading(d)))
            for f, d in zip(fields, range(0, 360, 30), strict=True)]
    lj.io.save_table(tmp_path / "flat.npz", lj.ResponseTable.from_simulations(
        sims, mount=mount, scan=scan, fields=fields))
    assert main(["calibrate", "--table", str(tmp_path / "flat.npz"), "--records", str(path),
                 "--wrt", "pitch,roll", "--period", "1min", "--min-availability", "0"]) == 0
    out = capsys.readouterr().out
    assert "header tilt: pitch 0.379 deg, roll 0.262 deg" in out
    assert "pitch" in out and "roll" in out


def test_calibrate_cli_exact_rebuilds_the_table_from_its_runs(case, capsys):
    # the instrument turned by 3 deg on its site and tilted by (1, -0.5) deg: records from
    # the table of the truly turned instrument (`TableRuns.table` of the same runs), and
    # `calibrate --exact` reads the runs again from the table file's metadata
    from lidarjax.workflows.seed_tables import table_runs

    settings = lj.io.read_settings(case / "settings.dat")
    table = lj.io.load_table(case / "plain.npz")
    runs = table_runs(settings.with_heights(np.asarray(table.heights)), settings.betas,
                      lambda b: lj.io.load_field(case / "runs" / f"d{b:g}_a0.npz"),
                      lj.windcube_v2())
    truth = np.array([3.0, 1.0, -0.5])
    rng = np.random.default_rng(80)
    n = 60
    u, d = rng.uniform(5, 12, n), rng.uniform(0, 360, n)
    los = u[:, None, None] * np.asarray(runs.table(truth).response_at(d))
    los = los + 0.02 * rng.standard_normal(los.shape)
    h = np.asarray(table.heights)
    times = _write_rtd(case / "exact.rtd", los, h)
    lines = ["time,height_m,speed_m_s,direction_deg"]
    for i, t in enumerate(times):
        lines += [f"{t},{z:g},{u[i]:.4f},{d[i]:.4f}" for z in h]
    (case / "exact_ref.csv").write_text("\n".join(lines) + "\n")
    out = case / "exact.json"
    assert main(["calibrate", "--table", str(case / "plain.npz"), "--records",
                 str(case / "exact.rtd"), "--reference", str(case / "exact_ref.csv"),
                 "--exact", "--min-availability", "0", "--out", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["rebuilds"] >= 1 and doc["flags"] == 0, doc["notes"]
    assert any("iterated on the exact geometry" in x for x in doc["notes"])
    err = np.abs(np.asarray(doc["offset_deg"]) - truth)
    assert np.all(err < 3 * np.asarray(doc["std_deg"]) + 1e-4), (doc["offset_deg"], doc["std_deg"])
    # a table over a profile parameter names no single set of runs
    assert main(["calibrate", "--table", str(case / "profile.npz"), "--records",
                 str(case / "exact.rtd"), "--exact", "--min-availability", "0"]) == 2
    assert "--exact" in capsys.readouterr().err
