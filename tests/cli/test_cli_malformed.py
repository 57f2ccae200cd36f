"""A catalogue of malformed inputs to the command line: each gives one line on stderr naming
the file or argument and exit 2 (never a traceback), or a flagged result with every good
record intact. Inputs are never overwritten; interrupted writes leave no temporary file.

Fast by design: `lidarjax.cli.main` runs in-process, the table is a small analytic one
(12 directions x 3 heights x 5 beams) written directly, and every correction shares one
compiled shape. Only the two signal tests start a subprocess.
"""

import copy
import json
import os
import signal
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.cli import main
from lidarjax.flags import RecordFlag
from lidarjax.io import Settings, save_table, write_settings, write_sta

HEIGHTS = np.array([40.0, 54.0, 74.0])
EPSILON = 21.0
N = 6


def _gain(d):
    """Speed-up of the analytic table, (s, h): smooth in direction, different per height."""
    return 1.0 - 0.05 * np.cos(np.deg2rad(d))[:, None] * (1 + 0.1 * np.arange(3))[None, :]


def _analytic_table():
    """A Windcube V2 table whose response is a mild, direction-dependent distortion."""
    scan = lj.windcube_v2()
    d = np.arange(0.0, 360.0, 30.0)
    vec = np.asarray(scan.directions())  # (b, 3) lidar frame
    free = np.stack([-np.sin(np.deg2rad(d)), -np.cos(np.deg2rad(d)), 0 * d], -1)  # (s, 3)
    rec = _gain(d)[..., None] * free[:, None, :]  # (s, h, 3)
    # beam vectors in the north frame: the lidar's +y (beam 0) points to EPSILON
    c, s_ = np.cos(np.deg2rad(-EPSILON)), np.sin(np.deg2rad(-EPSILON))
    rot = np.array([[c, -s_, 0], [s_, c, 0], [0, 0, 1]])
    nvec = vec @ rot.T
    response = np.einsum("shk,bk->shb", rec, nvec)
    table = lj.ResponseTable(d, response, reconstructed=rec, beam_vectors=nvec, heights=HEIGHTS)
    meta = {"scan": "windcube_v2", "scan_method": "windcube_v2", "cone_angle_deg": 28.0,
            "n_beams": 5, "vertical_beam": True, "probe": "point", "gamma_deg": 0.0,
            "psi_deg": 0.0, "epsilon_deg": EPSILON, "pitch_deg": 0.0, "roll_deg": 0.0,
            "heights_m": HEIGHTS.tolist()}
    return table, meta


@pytest.fixture(scope="module")
def case(tmp_path_factory):
    root = tmp_path_factory.mktemp("malformed")
    table, meta = _analytic_table()
    save_table(root / "table.npz", table, meta)
    rng = np.random.default_rng(1)
    u, d = rng.uniform(4, 14, N), rng.uniform(0, 360, N)
    # the table's reconstructed response is gain(d, h) along the free stream (numpy, no jit)
    speed = u[:, None] * _gain(d)
    direction = np.broadcast_to(d[:, None], speed.shape).copy()
    time = np.datetime64("2024-03-01T00:10") + np.arange(N) * np.timedelta64(10, "m")
    good = dict(time=time, heights=HEIGHTS, speed=speed, direction=direction,
                speed_std=np.full_like(speed, 0.6), availability=np.full_like(speed, 98.0))
    write_sta(root / "good.sta", scan_angle=28.0, direction_offset=EPSILON, **good)
    # a tiny seed case for table/simulate: 3 betas, small grid, 2 heights
    betas = np.array([0.0, 120.0, 240.0])
    write_settings(root / "settings.dat", Settings(
        zone=2, verbose=1, height=20.0, nh=2, gamma=0.0, beta=0.0, psi=0.0, epsilon=EPSILON,
        betas=betas, locations=np.tile([0.0, 0.0, 0.5], (3, 1))))
    x = np.linspace(-60, 60, 7)
    z = np.linspace(0, 100, 6)
    (root / "runs").mkdir()
    vel = np.zeros((7, 7, 6, 3))
    vel[..., 0] = -10.0
    for b in betas:
        np.savez(root / "runs" / f"p_{int(b)}.npz", x=x, y=x, z=z, velocity=vel)
    return {"root": root, "table": root / "table.npz", "good": good, "meta": meta,
            "truth": (u, d)}


def run_cli(argv, capsys):
    rc = main([str(a) for a in argv])
    cap = capsys.readouterr()
    return rc, cap.out, cap.err


def assert_one_line_error(rc, err, *needles):
    assert rc == 2, err
    lines = [ln for ln in err.strip().splitlines() if ln.strip()]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for n in needles:
        assert n in lines[0], (n, lines[0])


def correct_argv(case, records, *extra, out=None):
    out = out or Path(records).with_name(Path(records).stem + "_out.csv")
    return ["correct", "--table", case["table"], "--records", records, "--out", out,
            "--quiet", "--no-netcdf", *extra]


def read_csv(path):
    rows = [ln.split(",") for ln in Path(path).read_text().splitlines()
            if not ln.startswith(("#", "time"))]
    return np.array(rows)


# ------------------------------------------------------------------------------------------
# table files


def _npz(path, **arrays):
    with open(path, "wb") as fh:
        np.savez(fh, **arrays)
    return path


def _table_arrays(case):
    with np.load(case["table"]) as data:
        return {k: data[k] for k in data.files}


def _bad_tables(case, root):
    arrays = _table_arrays(case)
    raw = case["table"].read_bytes()
    out = {}
    (root / "truncated.npz").write_bytes(raw[: len(raw) // 2])
    out["truncated"] = (root / "truncated.npz", "truncated.npz")
    (root / "garbage.npz").write_bytes(b"\x00\x01 not a zip at all" * 10)
    out["garbage"] = (root / "garbage.npz", "garbage.npz")
    a = dict(arrays)
    a.pop("metadata")
    out["no_metadata"] = (_npz(root / "nometa.npz", **a), "metadata")
    out["meta_not_json"] = (_npz(root / "notjson.npz", **{**arrays, "metadata":
                                                        np.asarray("{scan: 28")}), "JSON")
    out["meta_list"] = (_npz(root / "metalist.npz", **{**arrays, "metadata":
                                                     np.asarray("[1, 2]")}), "JSON object")
    meta = json.loads(str(arrays["metadata"]))
    out["meta_cone_text"] = (_npz(root / "conetext.npz", **{**arrays, "metadata": np.asarray(
        json.dumps({**meta, "cone_angle_deg": "28"}))}), "cone_angle_deg")
    out["meta_eps_list"] = (_npz(root / "epslist.npz", **{**arrays, "metadata": np.asarray(
        json.dumps({**meta, "epsilon_deg": [21]}))}), "epsilon_deg")
    out["meta_format"] = (_npz(root / "fmt.npz", **{**arrays, "metadata": np.asarray(
        json.dumps({**meta, "format": "other"}))}), "format")
    out["response_2d"] = (_npz(root / "r2d.npz", **{**arrays, "response":
                                                  arrays["response"][:, 0]}), "response")
    out["response_complex"] = (_npz(root / "rc.npz", **{**arrays, "response":
                                                      arrays["response"] + 0j}), "complex")
    out["single_array"] = (root / "single.npy", "table")
    np.save(root / "single.npy", arrays["response"])
    return out


TABLE_CASES = ["truncated", "garbage", "no_metadata", "meta_not_json", "meta_list",
               "meta_cone_text", "meta_eps_list", "meta_format", "response_2d",
               "response_complex", "single_array"]


@pytest.fixture(scope="module")
def bad_tables(case):
    root = case["root"] / "tables"
    root.mkdir()
    return _bad_tables(case, root)


@pytest.mark.parametrize("name", TABLE_CASES)
def test_bad_table_file(case, bad_tables, capsys, name):
    path, needle = bad_tables[name]
    rc, _, err = run_cli(["correct", "--table", path, "--records", case["root"] / "good.sta",
                          "--out", case["root"] / f"t_{name}.csv", "--quiet"], capsys)
    assert_one_line_error(rc, err, str(path), needle)
    assert not (case["root"] / f"t_{name}.csv").exists()


def test_table_is_a_folder(case, capsys):
    rc, _, err = run_cli(["correct", "--table", case["root"] / "runs", "--records",
                          case["root"] / "good.sta", "--quiet"], capsys)
    assert_one_line_error(rc, err, "runs")


# ------------------------------------------------------------------------------------------
# numeric options


@pytest.mark.parametrize("extra, needle", [
    (["--noise", "inf"], "--noise"),
    (["--noise", "-1"], "--noise"),
    (["--noise", "0"], "--noise"),
    (["--noise", "nan"], "--noise"),
    (["--noise", "abc"], "--noise"),
    (["--scan-period", "0"], "--scan-period"),
    (["--cnr-threshold", "nan"], "--cnr-threshold"),
    (["--min-availability", "150"], "--min-availability"),
])
def test_bad_correct_option(case, capsys, extra, needle):
    rc, _, err = run_cli(correct_argv(case, case["root"] / "good.sta", *extra), capsys)
    assert_one_line_error(rc, err, needle)


def _table_argv(case, *extra, out=None):
    root = case["root"]
    return ["table", root / "settings.dat", "--field", root / "runs" / "p_{beta}.npz",
            "--out", out or root / "tab_out.npz", *extra]


@pytest.mark.parametrize("extra, needle", [
    (["--u-ref", "0,0,0"], "--u-ref"),
    (["--u-ref", "0,0,5"], "horizontal"),
    (["--u-ref", "1,2"], "--u-ref"),
    (["--u-ref", "nan,0,0"], "--u-ref"),
    (["--probe-scale", "nan"], "--probe-scale"),
    (["--probe-scale", "0"], "--probe-scale"),
    (["--probe-scale", "-2"], "--probe-scale"),
    (["--probe", "pulsed", "--probe-scale", "inf"], "--probe-scale"),
    (["--probe-nodes", "5"], "point"),
    (["--probe-scale", "100"], "point"),
    (["--probe", "cw", "--probe-nodes", "0"], "--probe-nodes"),
    (["--cone-angle", "-5"], "--cone-angle"),
    (["--cone-angle", "95"], "cone"),
    (["--heights", "40,30"], "--heights"),
    (["--heights", "abc"], "--heights"),
    (["--heights", "-5,10"], "--heights"),
    (["--heights-from", "nowhere.sta"], "nowhere.sta"),
])
def test_bad_table_option(case, capsys, extra, needle):
    rc, _, err = run_cli(_table_argv(case, *extra), capsys)
    assert_one_line_error(rc, err, needle)
    assert not (case["root"] / "tab_out.npz").exists()


@pytest.mark.parametrize("pattern, needle", [
    ("p_{1}.npz", "{1}"),
    ("p_{b}.npz", "{b}"),
    ("p_{beta.npz", "--field"),
    ("p_{beta:x}.npz", "--field"),
    ("p_}{beta}.npz", "--field"),
])
def test_bad_field_pattern(case, capsys, pattern, needle):
    root = case["root"]
    rc, _, err = run_cli(["table", root / "settings.dat", "--field", str(root / "runs" / pattern),
                          "--out", root / "tab_out.npz"], capsys)
    assert_one_line_error(rc, err, needle)


# ------------------------------------------------------------------------------------------
# settings and fields


def _settings_text(values="2\t0\t20\t2\t0\t0\t0\t21", extra=""):
    rows = "0\t0\t0\t0.5\n120\t0\t0\t0.5\n240\t0\t0\t0.5\n"
    return f"zone\tverbose\theight\tnh\tgamma\tbeta\tpsi\tepsilon\n{values}\n{extra}{rows}"


@pytest.mark.parametrize("text, needle", [
    (_settings_text("2\t0\t20\t100000000\t0\t0\t0\t21"), "limit"),
    (_settings_text(extra="heights\t10\t15\t20\n"), "nh"),
    (_settings_text(extra="heights\t20\t10\n"), "increasing"),
    (_settings_text("2\t0\t20\t2\t0\t0\t0\tnan"), "epsilon"),
])
def test_bad_settings(case, capsys, text, needle):
    path = case["root"] / "bad_settings.dat"
    path.write_text(text)
    rc, _, err = run_cli(["table", path, "--field", case["root"] / "runs" / "p_{beta}.npz",
                          "--out", case["root"] / "tab_out.npz"], capsys)
    assert_one_line_error(rc, err, "bad_settings.dat", needle)


@pytest.mark.parametrize("kind", ["complex", "float16", "truncated", "text"])
def test_bad_field_file(case, capsys, kind):
    root = case["root"] / f"fields_{kind}"
    root.mkdir()
    x = np.linspace(-30, 30, 7)
    vel = np.zeros((7, 7, 7, 3))
    vel[..., 0] = -10.0
    for b in (0, 120, 240):
        p = root / f"p_{b}.npz"
        if kind == "complex":
            np.savez(p, x=x, y=x, z=x + 30, velocity=vel + 1j)
        elif kind == "float16":
            np.savez(p, x=x, y=x, z=x + 30, velocity=vel.astype(np.float16))
        elif kind == "truncated":
            np.savez(p, x=x, y=x, z=x + 30, velocity=vel)
            p.write_bytes(p.read_bytes()[:300])
        else:
            p.write_text("hello")
    rc, _, err = run_cli(["table", case["root"] / "settings.dat", "--field",
                          root / "p_{beta}.npz", "--out", case["root"] / "tab_out.npz"], capsys)
    assert_one_line_error(rc, err, "p_0.npz")


# ------------------------------------------------------------------------------------------
# records: refused files and flagged records


def test_missing_and_unknown_record_files(case, capsys):
    rc, _, err = run_cli(correct_argv(case, case["root"] / "nowhere.sta"), capsys)
    assert_one_line_error(rc, err, "nowhere.sta")
    odd = case["root"] / "records.txt"
    odd.write_text("hello\n")
    rc, _, err = run_cli(correct_argv(case, odd), capsys)
    assert_one_line_error(rc, err, "records.txt", ".sta")


def test_empty_sta(case, capsys):
    p = case["root"] / "empty.sta"
    p.write_text("")
    rc, _, err = run_cli(correct_argv(case, p), capsys)
    assert_one_line_error(rc, err, "empty.sta")


@pytest.mark.parametrize("header, needle", [
    (dict(scan_angle=15.0), "ScanAngle=15"),
    (dict(direction_offset=-37.0), "DirectionOffset=-37"),
])
def test_instrument_mismatch_is_refused_naming_both(case, capsys, header, needle):
    kw = dict(scan_angle=28.0, direction_offset=EPSILON)
    kw.update(header)
    p = case["root"] / f"mismatch_{needle[:4]}.sta"
    write_sta(p, **case["good"], **kw)
    rc, _, err = run_cli(correct_argv(case, p), capsys)
    assert_one_line_error(rc, err, needle, "table")
    # with --allow-mismatch it corrects and says what it allowed
    rc, _, err = run_cli(correct_argv(case, p, "--allow-mismatch"), capsys)
    assert rc == 0 and "mismatch allowed" in err


def test_zephir_records_with_a_windcube_table(case, capsys):
    p = case["root"] / "zephir.csv"
    g = case["good"]
    lines = ["Time and Date;" + ";".join(
        f"Horizontal Wind Speed (m/s) at {h:g}m;Wind Direction (deg) at {h:g}m" for h in HEIGHTS)]
    for i, t in enumerate(g["time"]):
        stamp = str(t.astype("datetime64[s]")).replace("T", " ")
        cells = [f"{g['speed'][i, j]:.2f};{g['direction'][i, j]:.1f}".replace(".", ",")
                 for j in range(3)]
        lines.append(stamp + ";" + ";".join(cells))
    p.write_text("\n".join(lines) + "\n")
    rc, _, err = run_cli(correct_argv(case, p), capsys)
    assert_one_line_error(rc, err, "windcube_v2", "zephir")


def test_no_common_heights(case, capsys):
    p = case["root"] / "heights.sta"
    g = dict(case["good"], heights=np.array([100.0, 120.0, 140.0]))
    write_sta(p, **g, scan_angle=28.0, direction_offset=EPSILON)
    rc, _, err = run_cli(correct_argv(case, p), capsys)
    assert_one_line_error(rc, err, "heights.sta", "--heights-from")


def test_partial_heights_are_named_and_the_rest_corrected(case, capsys):
    g = case["good"]
    p = case["root"] / "partial.sta"
    heights = np.array([40.0, 54.0, 60.0, 74.0, 200.0])
    cols = {k: np.insert(np.concatenate([g[k], np.full((N, 1), 5.0)], axis=1), 2, 5.0, axis=1)
            for k in ("speed", "direction", "speed_std", "availability")}
    write_sta(p, time=g["time"], heights=heights, **cols, scan_angle=28.0,
              direction_offset=EPSILON)
    out = case["root"] / "partial_out.csv"
    rc, _, err = run_cli(correct_argv(case, p, out=out), capsys)
    assert rc == 0
    named = [ln for ln in err.splitlines() if "has no heights 60, 200" in ln]
    assert len(named) == 1
    body = read_csv(out)
    assert body.shape == (N * 3, 13)
    np.testing.assert_allclose(body[:, 2].astype(float).reshape(N, 3), case["truth"][0][:, None]
                               * np.ones((1, 3)), atol=5e-3)


@pytest.mark.parametrize("name, edit, column, flag", [
    ("negative", lambda s, d, a: s.__setitem__((2, 1), -3.0), 8, RecordFlag.IMPOSSIBLE_VALUE),
    ("dir400", lambda s, d, a: d.__setitem__((2, 1), 400.0), 8, RecordFlag.IMPOSSIBLE_VALUE),
    ("dirneg", lambda s, d, a: d.__setitem__((2, 1), -10.0), 8, RecordFlag.IMPOSSIBLE_VALUE),
    ("lowavail", lambda s, d, a: a.__setitem__((2, 1), 20.0), 8, RecordFlag.LOW_AVAILABILITY),
    ("nan", lambda s, d, a: s.__setitem__((2, 1), np.nan), 7, lj.InverseFlag.TOO_FEW_BEAMS),
])
def test_bad_value_is_flagged_good_rows_untouched(case, capsys, name, edit, column, flag):
    g = case["good"]
    speed, direction, avail = g["speed"].copy(), g["direction"].copy(), g["availability"].copy()
    edit(speed, direction, avail)
    p = case["root"] / f"bad_{name}.sta"
    write_sta(p, time=g["time"], heights=HEIGHTS, speed=speed, direction=direction,
              speed_std=g["speed_std"], availability=avail, scan_angle=28.0,
              direction_offset=EPSILON)
    out = case["root"] / f"bad_{name}_out.csv"
    rc, text, _ = run_cli(correct_argv(case, p, out=out), capsys)
    assert rc == 0
    body = read_csv(out)
    assert body.shape == (N * 3, 13)  # every record comes back
    got = body[:, 2].astype(float).reshape(N, 3)
    flags = body[:, column].astype(int).reshape(N, 3)
    assert np.isnan(got[2, 1]) and flags[2, 1] & int(flag)
    ok = np.ones((N, 3), bool)
    ok[2, 1] = False
    u = np.broadcast_to(case["truth"][0][:, None], (N, 3))
    np.testing.assert_allclose(got[ok], u[ok], atol=5e-3)  # the spline of 12 directions
    assert np.all(body[:, 7:9].astype(int).reshape(N, 3, 2)[ok] == 0)
    assert flag.name.lower() in text  # the quality summary counts it


def test_csv_and_netcdf_are_self_describing(case, capsys):
    import xarray as xr
    out = case["root"] / "cf_out.csv"
    argv = [a for a in correct_argv(case, case["root"] / "good.sta", out=out) if a != "--no-netcdf"]
    rc, text, _ = run_cli(argv, capsys)
    assert rc == 0 and "converged 18 of 18" in text
    head = [ln for ln in out.read_text().splitlines() if ln.startswith("#")]
    assert any("record_flags (RecordFlag bits)" in ln for ln in head)
    with xr.open_dataset(out.with_suffix(".nc")) as ds:
        assert ds.attrs["Conventions"].startswith("CF")
        assert ds["speed"].attrs["standard_name"] == "wind_speed"
        assert ds["direction"].attrs["standard_name"] == "wind_from_direction"
        for name, kind in (("flags", lj.InverseFlag), ("record_flags", RecordFlag)):
            masks = [int(m) for m in ds[name].attrs["flag_masks"]]
            meanings = ds[name].attrs["flag_meanings"].split()
            assert masks == [int(f) for f in kind if f]
            assert meanings == [f.name.lower() for f in kind if f]
        np.testing.assert_allclose(ds["speed"].values, case["truth"][0][:, None] * np.ones(3),
                                   atol=5e-3)
        assert np.all(ds["speed_std"].values > 0)  # from the dispersion, not NaN


# ------------------------------------------------------------------------------------------
# files: inputs never overwritten, outputs checked before computing


def test_correct_out_equal_to_records_is_refused(case, capsys):
    src = case["root"] / "good.sta"
    before = src.read_bytes()
    rc, _, err = run_cli(correct_argv(case, src, out=src), capsys)
    assert_one_line_error(rc, err, "good.sta", "input")
    assert src.read_bytes() == before


def test_correct_out_symlink_to_table_is_refused(case, capsys):
    link = case["root"] / "link.csv"
    if not link.exists():
        link.symlink_to(case["table"])
    before = case["table"].read_bytes()
    rc, _, err = run_cli(correct_argv(case, case["root"] / "good.sta", out=link), capsys)
    assert_one_line_error(rc, err, "link.csv", "table.npz")
    assert case["table"].read_bytes() == before


def test_netcdf_out_equal_to_records_is_refused(case, capsys):
    src = case["root"] / "good.sta"
    argv = [a for a in correct_argv(case, src) if a != "--no-netcdf"] + ["--netcdf", str(src)]
    rc, _, err = run_cli(argv, capsys)
    assert_one_line_error(rc, err, "--netcdf", "good.sta")


@pytest.mark.parametrize("target", ["settings", "field"])
def test_table_out_onto_an_input_is_refused(case, capsys, target):
    root = case["root"]
    path = root / "settings.dat" if target == "settings" else root / "runs" / "p_120.npz"
    before = path.read_bytes()
    rc, _, err = run_cli(_table_argv(case, out=path), capsys)
    assert_one_line_error(rc, err, path.name, "input")
    assert path.read_bytes() == before


def test_outputs_checked_before_computing(case, capsys, tmp_path):
    good = case["root"] / "good.sta"
    # onto a folder
    rc, _, err = run_cli(correct_argv(case, good, out=tmp_path), capsys)
    assert_one_line_error(rc, err, "folder")
    # into a missing folder
    rc, _, err = run_cli(correct_argv(case, good, out=tmp_path / "no" / "x.csv"), capsys)
    assert_one_line_error(rc, err, "not found")
    # into a folder nobody can write (a read-only file system, even for root)
    rc, _, err = run_cli(correct_argv(case, good, out="/proc/lidarjax_out.csv"), capsys)
    assert_one_line_error(rc, err, "/proc")
    # onto an existing read-only file
    ro = tmp_path / "ro.csv"
    ro.write_text("keep me\n")
    ro.chmod(0o444)
    rc, _, err = run_cli(correct_argv(case, good, out=ro), capsys)
    assert_one_line_error(rc, err, "read-only")
    assert ro.read_text() == "keep me\n"
    # simulate --out onto an existing file
    f = tmp_path / "afile"
    f.write_text("x")
    rc, _, err = run_cli(["simulate", case["root"] / "settings.dat", "--field",
                          case["root"] / "runs" / "p_{beta}.npz", "--all", "--out", f], capsys)
    assert_one_line_error(rc, err, "afile", "not a folder")


def test_usage_errors_are_one_line(capsys):
    rc, _, err = run_cli(["correct", "--table"], capsys)
    assert_one_line_error(rc, err, "--table")
    rc, _, err = run_cli(["nosuchcommand"], capsys)
    assert_one_line_error(rc, err, "nosuchcommand")


# ------------------------------------------------------------------------------------------
# table and simulate on the tiny seed case


def test_table_heights_and_metadata(case, capsys):
    out = case["root"] / "tab_heights.npz"
    rc, _, err = run_cli(_table_argv(case, "--heights-from", case["root"] / "good.sta",
                                     out=out), capsys)
    assert rc == 0, err
    table, meta = lj.io.load_table(out, return_metadata=True)
    np.testing.assert_allclose(table.heights, HEIGHTS)
    assert meta["scan"] == "windcube_v2" and meta["cone_angle_deg"] == 28.0
    assert meta["n_beams"] == 5 and meta["epsilon_deg"] == EPSILON
    assert meta["heights_m"] == HEIGHTS.tolist() and len(meta["cfd_files"]) == 3


def test_simulate_writes_flags_and_explains_nan(case, capsys):
    root = case["root"]
    settings = root / "settings_high.dat"
    # three heights like the table test (one compiled shape); 150 m is above the 100 m grid
    settings.write_text(_settings_text("2\t1\t150\t3\t0\t0\t0\t21",
                                       "heights\t40\t54\t150\n"))
    out = root / "sim_out"
    rc, _, err = run_cli(["simulate", settings, "--field", root / "runs" / "p_{beta}.npz",
                          "--all", "--out", out], capsys)
    assert rc == 0, err
    warn = [ln for ln in err.splitlines() if "3 of 9 height-runs are NaN" in ln]
    assert len(warn) == 1 and "grid is too low" in warn[0]
    cols = lj.io.read_seed_output(out / "windcube simulation 0 degrees.dat")
    outside = [False, False, True]  # only the top height leaves the grid
    assert list(cols["flags"].astype(int) & int(lj.Flag.BEAM_OUTSIDE) > 0) == outside
    assert np.isnan(cols["U_mag_lidar"][2]) and np.isfinite(cols["U_mag_lidar"][:2]).all()
    csv = lj.io.read_table_csv(out / "simulation_0.csv")
    assert list(csv.columns["flags"].astype(int) & int(lj.Flag.BEAM_OUTSIDE) > 0) == outside
    if (out / "simulation_0.nc").exists():
        import xarray as xr
        with xr.open_dataset(out / "simulation_0.nc") as ds:
            assert list(ds["flags"].values.astype(int) & int(lj.Flag.BEAM_OUTSIDE) > 0) == outside


# ------------------------------------------------------------------------------------------
# signals: the only subprocess tests

_SLOW_WRITER = textwrap.dedent("""
    import signal, sys, time
    import numpy as np
    import lidarjax.workflows.records as r

    # Ctrl-C as in a terminal: a shell that starts the test suite in the background starts it
    # with SIGINT ignored, which the child inherits (it then slept its 60 s and the test
    # timed out)
    signal.signal(signal.SIGINT, signal.default_int_handler)

    def fake_correct(table, path, *, records=None, **kw):  # no compilation: about the writer
        z = np.zeros(records.speed.shape)
        return r.CorrectedRecords(
            kind=records.kind, time=records.time, heights=records.heights, speed=records.speed,
            direction=records.direction, speed_std=z, direction_std=z, converged=z == 0,
            flags=z.astype(int), measured_speed=records.speed,
            measured_direction=records.direction)

    r.correct_records = fake_correct
    real = r._progress
    def slow(label, enabled):
        show = real(label, False)
        def step(done, total):
            if label.startswith("writing") and done > 0:
                print("READY", flush=True)
                time.sleep(60)
            show(done, total)
        return step
    r._progress = slow
    from lidarjax.cli import main
    sys.exit(main(sys.argv[1:]))
""")


@pytest.mark.parametrize("sig, code", [(signal.SIGTERM, 143), (signal.SIGINT, 130)])
def test_interrupted_write_leaves_no_temporary_file(case, tmp_path, sig, code):
    out = tmp_path / "out.csv"
    env = dict(os.environ, PYTHONPATH=str(Path(lj.__file__).parent.parent), LIDARJAX_NO_CACHE="1")
    argv = [str(a) for a in correct_argv(case, case["root"] / "good.sta", out=out)]
    argv.remove("--quiet")
    proc = subprocess.Popen([sys.executable, "-c", _SLOW_WRITER, *argv], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    try:
        for line in proc.stdout:
            if line.strip() == "READY":
                break
        assert list(tmp_path.iterdir()), "the temporary file should exist while writing"
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
    finally:  # never leave the child running (its warnings would land in another test)
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()
    assert proc.returncode == code, err
    assert "Traceback" not in err
    last = [ln for ln in err.splitlines() if ln.strip()][-1]
    assert "interrupted" in last or "terminated" in last
    assert list(tmp_path.iterdir()) == []  # neither the output nor a temporary file


def test_zip_member_corruption_in_table(case, capsys, tmp_path):
    # a valid zip whose member is cut: caught when the array is read, not when opened
    arrays = _table_arrays(case)
    path = tmp_path / "cut.npz"
    with zipfile.ZipFile(path, "w") as zf:
        for k, v in arrays.items():
            import io as _io

            buf = _io.BytesIO()
            np.save(buf, v)
            data = buf.getvalue()
            zf.writestr(f"{k}.npy", data[: len(data) // 2] if k == "response" else data)
    rc, _, err = run_cli(["correct", "--table", path, "--records", case["root"] / "good.sta",
                          "--out", tmp_path / "o.csv", "--quiet"], capsys)
    assert_one_line_error(rc, err, "cut.npz")


def test_compilation_cache_folder_and_opt_out(monkeypatch, tmp_path):
    import argparse

    import jax

    from lidarjax.cli._common import setup_compilation_cache

    before = jax.config.jax_compilation_cache_dir
    assert before is None  # importing lidarjax (and running the CLI tests) leaves JAX alone
    try:
        monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
        monkeypatch.setenv("LIDARJAX_NO_CACHE", "1")
        assert setup_compilation_cache(argparse.Namespace(no_cache=False)) is None
        monkeypatch.setenv("LIDARJAX_NO_CACHE", "0")
        assert setup_compilation_cache(argparse.Namespace(no_cache=True)) is None
        assert jax.config.jax_compilation_cache_dir is None
        folder = setup_compilation_cache(argparse.Namespace(no_cache=False))
        assert folder == tmp_path / "lidarjax" / "jax" and folder.is_dir()
        assert jax.config.jax_compilation_cache_dir == str(folder)
    finally:
        jax.config.update("jax_compilation_cache_dir", before)


def test_old_table_without_metadata_warns_and_corrects(case, capsys, tmp_path):
    table = lj.io.load_table(case["table"])
    old = tmp_path / "old_table.npz"
    # as written before the instrument facts: the scan's name only
    bare = copy.copy(table)
    object.__setattr__(bare, "instrument", None)
    save_table(old, bare, {"scan": "windcube_v2"})
    out = tmp_path / "old_out.csv"
    rc, text, err = run_cli(["correct", "--table", old, "--records", case["root"] / "good.sta",
                             "--out", out, "--quiet", "--no-netcdf"], capsys)
    assert rc == 0 and "converged 18 of 18" in text
    warn = [ln for ln in err.splitlines() if "cannot be checked" in ln]
    assert len(warn) == 1 and "cone_angle_deg" in warn[0]


# ------------------------------------------------------------------------------------------
# missing inputs: named as missing when the arguments are parsed (issue 37)

MISSING = "no_such_input"
FIELD = "CFD field file or folder not found"
#: every input path argument of every command, `M` where the missing path goes; the other
#: inputs exist (`s.dat`, `f.csv`: placeholders, never read: parsing stops at the missing one)
_MISSING_INPUTS = [
    ("series", ["s.dat", "--sequence", "M"], "--sequence", "OpenFOAM case not found"),
    ("series", ["M"], "settings", "file not found"),
    ("series", ["s.dat", "--field", "M"], "--field", FIELD),
    ("series", ["s.dat", "--field", "f.csv", "--box", "f.csv,M,f.csv"], "--box", "file not found"),
    ("series", ["s.dat", "--motion", "M"], "--motion", "file not found"),
    ("series", ["s.dat", "--scan", "M.hpl"], "--scan", "file not found"),
    ("simulate", ["M", "--field", "f.csv"], "settings", "file not found"),
    ("simulate", ["s.dat", "--field", "M"], "--field", FIELD),
    ("simulate", ["s.dat", "--field", "f.csv", "--scan", "M.nc"], "--scan", "file not found"),
    ("table", ["M", "--field", "f.csv", "--out", "t.npz"], "settings", "file not found"),
    ("table", ["s.dat", "--field", "M", "--out", "t.npz"], "--field", FIELD),
    ("table", ["s.dat", "--field", "f.csv", "--heights-from", "M", "--out", "t.npz"],
     "--heights-from", "file not found"),
    ("correct", ["--table", "M", "--records", "f.csv"], "--table", "file not found"),
    ("correct", ["--table", "f.csv", "--records", "M"], "--records", "file not found"),
    ("calibrate", ["--table", "M", "--records", "f.csv"], "--table", "file not found"),
    ("calibrate", ["--table", "f.csv", "--records", "f.csv", "M"], "--records", "file not found"),
    ("calibrate", ["--table", "f.csv", "--records", "f.csv", "--reference", "M"], "--reference",
     "file not found"),
    ("monitor-points", ["M", "--out", "o"], "settings", "file not found"),
    ("monitor-points", ["s.dat", "--field", "M", "--out", "o"], "--field", FIELD),
    ("monitor-points", ["s.dat", "--sampled", "M", "--out", "o"], "--sampled",
     "file or folder not found"),
    ("sensitivity", ["M", "--field", "f.csv"], "settings", "file not found"),
    ("sensitivity", ["s.dat", "--field", "M"], "--field", FIELD),
    ("design", ["M", "--field", "f.csv", "--region", "box:0,1,0,1,0,1"], "settings",
     "file not found"),
    ("design", ["s.dat", "--field", "M", "--region", "box:0,1,0,1,0,1"], "--field", FIELD),
    ("farm", ["M", "--turbine", "f.csv", "--lidar", "0", "0", "0", "--out", "o"], "layouts",
     "file not found"),
    ("farm", ["f.csv", "--turbine", "M", "--lidar", "0", "0", "0", "--out", "o"], "--turbine",
     "file not found"),
    ("scan", ["M.hpl"], "scan", "file not found"),
    ("scan", ["ppi", "--field", "M"], "--field", FIELD),
]


@pytest.mark.parametrize(("command", "argv", "option", "text"), _MISSING_INPUTS,
                         ids=[f"{c}-{o}" for c, _, o, _ in _MISSING_INPUTS])
def test_a_missing_input_is_named_as_missing_when_parsed(tmp_path, monkeypatch, capsys, command,
                                                         argv, option, text):
    monkeypatch.chdir(tmp_path)
    Path("s.dat").write_text("not read\n")
    Path("f.csv").write_text("not read\n")
    missing = [a.replace("M", MISSING) if a in ("M", "M.hpl", "M.nc") or ",M," in a else a
               for a in argv]
    rc, _, err = run_cli([command, *missing], capsys)
    assert_one_line_error(rc, err, f"lidarjax {command}: error: argument {option}: {text}",
                          MISSING)


def test_every_input_path_argument_is_checked_when_parsed():
    """Each command's arguments that name an input file or folder carry a checking type (so
    a new one cannot slip in unchecked), and the catalogue above tries each of them."""
    from lidarjax.cli import _common, build_parser
    from lidarjax.cli._scanning import scan_choice, scan_source
    from lidarjax.cli.series import _mean_flow

    checked = {_common.input_file, _common.input_folder, _common.input_path,
               _common.input_case, _common.input_files, _common.field_input, scan_source,
               scan_choice, _mean_flow}
    inputs = {"settings", "field", "sequence", "box", "motion", "heights_from", "table",
              "records", "reference", "sampled", "layouts", "turbine", "scan"}
    parser = build_parser()
    commands = next(a for a in parser._actions if a.dest == "command").choices
    tried = {(c, o) for c, _, o, _ in _MISSING_INPUTS}
    seen = set()
    for name, sub in commands.items():
        if id(sub) in seen:  # an alias (probes: monitor-points)
            continue
        seen.add(id(sub))
        for action in sub._actions:
            if action.dest not in inputs or action.choices:  # --scan of fixed names
                continue
            assert action.type in checked, (name, action.dest)
            option = action.option_strings[0] if action.option_strings else action.dest
            assert (name, option) in tried, (name, option)


# ------------------------------------------------------------------------------------------
# warnings: one line each, `lidarjax COMMAND: warning: ...` (issue 37)


def test_a_library_warning_is_one_line_on_the_command_line(tmp_path, capsys):
    """A turbine curve with Ct >= 1 is clipped with a `UserWarning` (lidarjax.scenes.farm):
    on the command line it is one line without Python's source file and line, and the
    library still warns as before once the command is over. (The unknown --yaw turbine then
    stops the command before anything is simulated.)"""
    import warnings

    from lidarjax.io.layout import read_turbine_type

    (tmp_path / "a.txt").write_text("T001 251865.0 646486.0\n")
    (tmp_path / "t.csv").write_text("# rotor_diameter = 126\n# hub_height = 90\nspeed,ct\n"
                                    "3.0,1.13\n11.4,0.72\n25.0,0.06\n")
    argv = ["farm", tmp_path / "a.txt", "--turbine", tmp_path / "t.csv", "--lidar", "0", "0",
            "0", "--yaw", "T999=5", "--out", tmp_path / "o"]
    with warnings.catch_warnings():
        warnings.simplefilter("default")  # as a user's Python shows warnings
        rc, _, err = run_cli(argv, capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 2, err
    assert lines[0].startswith(f"lidarjax farm: warning: {tmp_path / 't.csv'}: Ct 0.06..1.13 "
                               "leaves [0, 1); clipped"), lines[0]
    assert "UserWarning" not in err and ".py:" not in err
    assert lines[1].startswith("lidarjax farm: error: --yaw 'T999=5'")
    with pytest.warns(UserWarning, match="clipped"):  # the library: a proper UserWarning
        read_turbine_type(tmp_path / "t.csv")


def test_a_scan_file_warning_names_the_command(tmp_path, capsys):
    """Warnings the command line catches itself (a truncated Halo file's reader) take the
    same form. (The field that is no field then stops the command before any simulation.)"""
    from ..io.test_hpl import RHI

    cut = tmp_path / "cut.hpl"
    cut.write_text("\n".join(RHI.read_text().splitlines()[:-5]) + "\n")  # last ray cut
    bad = tmp_path / "bad.npz"
    bad.write_text("not an archive")
    rc, _, err = run_cli(["scan", cut, "--field", bad, "--out", tmp_path / "s.nc"], capsys)
    lines = err.strip().splitlines()
    assert rc == 2 and len(lines) == 2, err
    assert lines[0].startswith(f"lidarjax scan: warning: {cut}, line 96: truncated file"), err
    assert lines[1].startswith("lidarjax scan: error:") and "bad.npz" in lines[1]


def test_height_table_of_no_finite_value_prints_nan_with_a_reason(capsys):
    """The per-height table of `lidarjax series`: a height where every record is NaN (or no
    records at all) prints nan and says why, without numpy's 'Mean of empty slice'."""
    import warnings

    from lidarjax.cli._common import print_height_means

    speed = np.array([[5.0, np.nan], [7.0, np.nan]])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        print_height_means([40.0, 80.0], {"U_lidar": (speed, 8, 3)})
        print_height_means([40.0], {"U_lidar": (np.zeros((0, 1)), 8, 3),
                                    "avail%": (np.zeros((0, 1)), 7, 1)})
    out = capsys.readouterr().out.splitlines()
    assert out[0].split() == ["height", "U_lidar"]
    assert out[1].split() == ["40.0", "6.000"] and out[2].split() == ["80.0", "nan"]
    assert out[3].startswith("nan: no finite record behind the mean (U_lidar;")
    assert out[5].split() == ["40.0", "nan", "nan"]
    assert out[6].startswith("nan: no finite record behind the mean (U_lidar, avail%;")
