"""Halo StreamLine `.hpl` files: the committed real cuts (tests/data/scanning/README.md),
checked against a plain independent parse, simulated in the same layout, and malformed
variants refused in one line naming the file and line."""

from __future__ import annotations

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import read_hpl

from ..helpers import DATA

STARE = DATA / "scanning" / "Stare_91_20221214_12.hpl"
VAD = DATA / "scanning" / "VAD_194_20210624_170110_cut.hpl"


def _plain(path):
    """Rays and gate rows by splitting lines: the independent reading."""
    lines = path.read_text().splitlines()
    end = next(i for i, line in enumerate(lines) if line.startswith("****"))
    body = [line.split() for line in lines[end + 1:] if line.strip()]
    rays = [i for i, f in enumerate(body) if len(f) == 5 and "." in f[0] and not f[0].isdigit()]
    return body, rays


@pytest.mark.parametrize("path", [STARE, VAD])
def test_real_files_match_an_independent_parse(path):
    scan = read_hpl(path)
    body, rays = _plain(path)
    assert scan.n_rays == len(rays)
    for k, i in enumerate(rays):
        np.testing.assert_allclose([scan.decimal_hours[k], scan.azimuth[k], scan.elevation[k],
                                    scan.pitch[k], scan.roll[k]], [float(x) for x in body[i]])
        gates = np.array([[float(x) for x in row[:4]] for row in body[i + 1:i + 1 + scan.n_gates]])
        np.testing.assert_array_equal(gates[:, 0], np.arange(scan.n_gates))
        np.testing.assert_allclose(scan.doppler[k], gates[:, 1])
        np.testing.assert_allclose(scan.intensity[k], gates[:, 2])
        np.testing.assert_allclose(scan.beta[k], gates[:, 3])
    np.testing.assert_allclose(scan.ranges, (np.arange(scan.n_gates) + 0.5) * scan.gate_length)


def test_header_fields_and_threshold():
    s = read_hpl(STARE)
    assert (s.n_gates, s.gate_length, s.scan_type, s.system_id) == (250, 48.0, "Stare", "91")
    assert s.start_time == np.datetime64("2022-12-14T12:00:20.64")
    assert s.spectral_width is None
    v = read_hpl(VAD)
    assert v.scan_type == "VAD" and v.spectral_width is not None and v.n_gates == 40
    # the ray time is hours after midnight of the start date
    np.testing.assert_allclose((v.time[0] - np.datetime64("2021-06-24")) / np.timedelta64(1, "s"),
                               17.02071944 * 3600, atol=1e-5)
    los = s.radial_velocity(1.02)
    keep = s.intensity >= 1.02
    assert 0 < keep.sum() < keep.size
    np.testing.assert_array_equal(np.isnan(los), ~keep)
    np.testing.assert_array_equal(los[keep], s.doppler[keep])


def test_simulated_scan_in_the_real_layout():
    """The VAD file's layout (its rays, gates and times) simulated in a uniform wind: same
    ranges and times, and the LOS of a level instrument are n . V with the file's angles
    (the file's pitch and roll given to the mount tilt the rays, as the instrument is)."""
    v = read_hpl(VAD)
    p = v.pattern()
    wind = lj.scenes.uniform(9.0, 230.0, w=0.2)
    res = lj.simulate_scan(wind, p, lj.Mount([0.0, 0.0, 0.0]), probe=lj.instrument_probe())
    assert res.los.shape == v.doppler.shape
    np.testing.assert_allclose(np.asarray(res.ranges), v.ranges)
    end = (v.time - v.reference_time()) / np.timedelta64(1, "us") * 1e-6
    np.testing.assert_allclose(np.asarray(res.times) + v.accumulation() / 2, end, atol=1e-6)
    n = np.asarray(lj.scanning.ray_unit_vectors(v.azimuth, v.elevation))
    vel = np.asarray(wind.sample(np.zeros(3)))
    np.testing.assert_allclose(np.asarray(res.los), np.repeat((n @ vel)[:, None], 40, 1), atol=1e-12)
    tilted = lj.simulate_scan(wind, p, lj.Mount([0.0, 0.0, 0.0], pitch=v.pitch[0], roll=v.roll[0]))
    assert 0 < np.max(np.abs(np.asarray(tilted.los) - np.asarray(res.los))) < 0.1


def _corrupt(tmp_path, path, fn):
    lines = path.read_text().splitlines()
    out = tmp_path / path.name
    out.write_text("\n".join(fn(lines)) + "\n")
    return out


@pytest.mark.parametrize("edit, where", [
    (lambda ls: [ls[0]] + ls[2:3] + ls[4:], None),  # header field missing (gate length)
    (lambda ls: [x.replace("Number of gates:\t40", "Number of gates:\tforty") for x in ls], 3),
    (lambda ls: ls[:18] + ["  0 -0.5351 1.2x8768  1.344642E-5 0.0764"] + ls[19:], 19),
    (lambda ls: ls[:19] + ls[20:], 20),  # gate 1 missing: gate 2 found where 1 expected
    (lambda ls: ls[:17] + ["17.0207 360.00 75.00"] + ls[18:], 18),
    (lambda ls: ls[:-5], None),  # last ray cut short
    (lambda ls: [x.replace("No. of rays in file:\t2", "No. of rays in file:\t6") for x in ls], None),
    (lambda ls: [x for x in ls if not x.startswith("****")], None),
])
def test_malformed_files_refused_in_one_line(tmp_path, edit, where):
    bad = _corrupt(tmp_path, VAD, edit)
    with pytest.raises(ValueError) as err:
        read_hpl(bad)
    msg = str(err.value)
    assert "\n" not in msg and str(bad) in msg
    if where is not None:
        assert f"line {where}:" in msg, msg


def test_empty_and_missing_files(tmp_path):
    (tmp_path / "e.hpl").write_text("")
    with pytest.raises(ValueError, match="e.hpl"):
        read_hpl(tmp_path / "e.hpl")
    with pytest.raises(FileNotFoundError):
        read_hpl(tmp_path / "none.hpl")
