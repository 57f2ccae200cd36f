"""`lidarjax correct` on the real Windcube files in ../shared/data/windcube/ (skipped when the
folder is absent): the .rtd is CNR-filtered like the instrument, the .sta comes back whole."""

from pathlib import Path

import numpy as np

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.io import save_table

from ..helpers import windcube_file


def real_file(name):
    return windcube_file(name)


def identity_table(path, heights, epsilon):
    """A table of an undisturbed site: the free stream is what a level Windcube V2 sees."""
    d = np.arange(0.0, 360.0, 10.0)
    r = np.deg2rad(d)
    free = np.stack([-np.sin(r), -np.cos(r), 0 * r], -1)
    rec = np.repeat(free[:, None, :], len(heights), 1)
    vec = np.asarray(lj.windcube_v2().directions())
    c, s = np.cos(np.deg2rad(-epsilon)), np.sin(np.deg2rad(-epsilon))
    vec = vec @ np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]).T  # beam 0 towards epsilon
    table = lj.ResponseTable(d, np.einsum("shk,bk->shb", rec, vec), reconstructed=rec,
                             beam_vectors=vec, heights=np.asarray(heights, float))
    save_table(path, table, {"scan": "windcube_v2", "cone_angle_deg": 28.0, "n_beams": 5,
                             "epsilon_deg": epsilon, "pitch_deg": 0.0, "roll_deg": 0.0,
                             "heights_m": list(map(float, heights))})


def body(path):
    return np.array([ln.split(",") for ln in Path(path).read_text().splitlines()
                     if not ln.startswith(("#", "time"))])


def test_real_rtd_is_cnr_filtered_like_the_instrument(tmp_path, capsys):
    rtd = real_file("WLS866-104_2024_08_02__23_44_55.rtd")
    identity_table(tmp_path / "t.npz", [40, 50, 60, 70, 100, 120, 150], 0.0)
    out = tmp_path / "rtd.csv"
    assert main(["correct", "--table", str(tmp_path / "t.npz"), "--records", str(rtd), "--out",
                 str(out), "--quiet"]) == 0
    rows = body(out)
    at40 = rows[rows[:, 1] == "40"]
    # the instrument reports about 7.2 m/s from about 92 degrees at 40 m; the vertical beam is
    # below CNRThreshold=-23 and must not enter (unfiltered it gave 4.1 m/s from 142 degrees)
    speed, direction = at40[:, 2].astype(float), at40[:, 3].astype(float)
    # the first interval (02:40-02:50 UTC) starts inside the file at 02:44:55: partial, half
    # its samples, so below the 80 % availability minimum: flagged and NaN, still listed
    rflags = rows[:, 8].astype(int).reshape(-1, 7)
    flag = lj.RecordFlag
    assert rflags[0, 0] & int(flag.PARTIAL_INTERVAL) and rflags[0, 0] & int(flag.LOW_AVAILABILITY)
    assert np.isnan(speed[0])
    # the full interval ending 03:00 UTC: the instrument's own per-line reconstruction
    # averages 7.49 m/s from 91.6 degrees at 40 m. The vertical beam is below CNRThreshold=-23
    # and must not enter (unfiltered, the correction gave 4.1 m/s from 142 degrees)
    assert at40[1, 0] == "2024-08-03T03:00:00Z"
    assert abs(speed[1] - 7.49) < 0.1 and abs(direction[1] - 91.6) < 1.5, (speed, direction)
    # the header's tilt (PitchAngle=0.379, RollAngle=0.262) differs from the level table: shown
    err = capsys.readouterr().err
    assert "tilt: pitch 0.379 deg in the record header, 0 in the table; roll 0.262" in err


def test_tilt_from_record_headers(tmp_path):
    """`table --tilt-from-records` takes the header's pitch and roll; `correct` stays quiet
    about the tilt when the table has it."""
    from argparse import Namespace

    from lidarjax.cli.table import _tilt_from
    from lidarjax.workflows.records import load_records, tilt_difference

    rec = load_records(real_file("WLS866-104_2024_08_02__23_44_55.rtd"))
    args = Namespace(pitch=0.0, roll=0.0, heights_from="x.rtd")
    _tilt_from(args, rec)
    assert (args.pitch, args.roll) == (0.379, 0.262)
    assert tilt_difference({"pitch_deg": 0.379, "roll_deg": 0.262}, rec) is None
    assert "pitch 0.379" in tilt_difference({"pitch_deg": 0.0, "roll_deg": 0.0}, rec)


def test_real_sta_every_record_comes_back(tmp_path, capsys):
    sta = real_file("wls7_abc_2020_10_07__00_10_00.sta")
    heights = [40, 54, 74, 84, 94, 110, 115, 134, 154, 174, 194, 220]
    identity_table(tmp_path / "t.npz", heights, 0.0)
    out = tmp_path / "sta.csv"
    # the file's DirectionOffset is -37: a table with epsilon 0 is refused, naming both
    assert main(["correct", "--table", str(tmp_path / "t.npz"), "--records", str(sta),
                 "--out", str(out), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "DirectionOffset=-37" in err and "epsilon 0" in err
    identity_table(tmp_path / "t.npz", heights, -37.0)
    assert main(["correct", "--table", str(tmp_path / "t.npz"), "--records", str(sta),
                 "--out", str(out), "--quiet"]) == 0
    rows = body(out)
    assert rows.shape[0] == 144 * 12  # every record and height, good or not
    rec = lj.io.read_sta(sta)
    ok = rows[:, 6] == "True"
    reported = np.asarray(rec.speed).ravel()
    # an undisturbed table corrects nothing: where used, the free stream is what was reported
    np.testing.assert_allclose(rows[ok, 2].astype(float), reported[ok], atol=2e-3)
    assert np.all(np.isfinite(rows[ok, 4].astype(float)))  # uncertainty from the dispersion
