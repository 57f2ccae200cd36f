"""Halo StreamLine `.hpl` files (tests/data/scanning/README.md): the committed real RHI with
overlapping gates, and a real stare and VAD where available (`scanning_file`: cuts of public
repositories kept outside the project), checked against a plain independent parse,
simulated in the same layout, and malformed variants refused in one line naming the file
and line."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import read_hpl

from ..helpers import SCANNING, scanning_file

STARE = "Stare_91_20221214_12.hpl"
VAD = "VAD_194_20210624_170110_cut.hpl"
RHI = SCANNING / "RHI_77_20260921_000812.hpl"


def _plain(path):
    """Rays and gate rows by splitting lines: the independent reading."""
    lines = path.read_text().splitlines()
    end = next(i for i, line in enumerate(lines) if line.startswith("****"))
    body = [line.split() for line in lines[end + 1:] if line.strip()]
    rays = [i for i, f in enumerate(body) if len(f) == 5 and "." in f[0] and not f[0].isdigit()]
    return body, rays


@pytest.mark.parametrize("path, first, spacing", [
    (STARE, 24.0, 48.0),  # (gate + 0.5) * 48 m
    (VAD, 15.0, 30.0),  # (gate + 0.5) * 30 m
    (RHI, 9.0, 3.0),  # 18 m / 2 + gate x 3 m: overlapping gates, one 3 m sampling point apart
])
def test_real_files_match_an_independent_parse(path, first, spacing):
    path = path if isinstance(path, Path) else scanning_file(path)
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
    np.testing.assert_allclose(scan.ranges, first + spacing * np.arange(scan.n_gates))
    assert scan.gate_spacing == spacing


def test_header_fields_and_threshold():
    s = read_hpl(scanning_file(STARE))
    assert (s.n_gates, s.gate_length, s.scan_type, s.system_id) == (250, 48.0, "Stare", "91")
    assert s.start_time == np.datetime64("2022-12-14T12:00:20.64")
    assert s.spectral_width is None
    v = read_hpl(scanning_file(VAD))
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
    v = read_hpl(scanning_file(VAD))
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


def test_real_rhi_geometry_and_simulation_in_its_layout():
    """The Trier RHI (system 77): one azimuth, elevations stepped 0 to 45 degrees by 15,
    18 m gates every 3 m, rays 4.2 to 4.3 s apart (2 s accumulations: step and stare). Its
    layout simulated in a linearly sheared wind gives, per gate, the LOS at the gate centre
    (the pulsed average of a linear field along the beam is exact), computed here with
    numpy from the file's angles and ranges; same ranges, same ray times."""
    r = read_hpl(RHI)
    assert r.scan_type == "RHI - overlapping" and r.system_id == "77"
    assert (r.n_rays, r.n_gates, r.gate_length, r.gate_points) == (4, 20, 18.0, 6)
    np.testing.assert_array_equal(r.azimuth, 255.0)
    np.testing.assert_array_equal(r.elevation, [0.0, 15.0, 30.0, 45.0])
    assert np.all(np.abs(r.pitch) < 0.2) and np.all(np.abs(r.roll) < 0.25)
    gaps = np.diff(r.seconds())
    assert np.all((gaps > 4.1) & (gaps < 4.4)) and r.accumulation() == 2.0
    # as in the other committed files, the header's start time is after the first ray's time
    assert 1.0 < (r.start_time - r.time[0]) / np.timedelta64(1, "s") < 1.1
    p = r.pattern()
    assert p.kind == "rhi"
    v0, grad = np.array([-6.0, -2.0, 0.1]), np.zeros((3, 3))
    grad[0, 2], grad[1, 2], grad[0, 0] = 0.05, -0.02, 0.003  # du/dz, dv/dz, du/dx (1/s)
    field = lj.scenes.linear(v0, grad)
    probe = lj.instrument_probe(gate_length=r.gate_length)
    res = lj.simulate_scan(field, p, lj.Mount([0.0, 0.0, 0.0]), probe=probe)
    assert res.los.shape == r.doppler.shape == (4, 20)
    np.testing.assert_allclose(np.asarray(res.ranges), r.ranges)
    end = (r.time - r.reference_time()) / np.timedelta64(1, "us") * 1e-6
    np.testing.assert_allclose(np.asarray(res.times) + r.accumulation() / 2, end, atol=1e-6)
    a, e = np.radians(r.azimuth), np.radians(r.elevation)
    n = np.stack([np.cos(e) * np.sin(a), np.cos(e) * np.cos(a), np.sin(e)], axis=1)  # (r, 3)
    pts = r.ranges[None, :, None] * n[:, None, :]  # (r, g, 3) gate centres
    expect = np.einsum("ri,rgi->rg", n, v0 + pts @ grad.T)
    np.testing.assert_allclose(np.asarray(res.points), pts, atol=1e-9)
    np.testing.assert_allclose(np.asarray(res.los), expect, atol=1e-10)
    # gates this near the lidar: the pulse reaches it and is cut symmetrically (still exact
    # for a linear field), flagged on the near gates only
    flags = np.asarray(res.flags)
    near = (flags & int(lj.Flag.PROBE_TRUNCATED)) != 0
    assert np.all(near == near[:1]) and 0 < near[0].sum() < r.n_gates
    assert np.all(near[0] == (np.arange(r.n_gates) < near[0].sum()))
    # the RHI plane: every gate centre in the vertical plane through azimuth 255
    normal = np.array([np.cos(a[0]), -np.sin(a[0]), 0.0])
    np.testing.assert_allclose(np.asarray(res.points) @ normal, 0.0, atol=1e-9)


def _corrupt(tmp_path, path, fn):
    lines = path.read_text().splitlines()
    out = tmp_path / path.name
    out.write_text("\n".join(fn(lines)) + "\n")
    return out


@pytest.mark.parametrize("edit, where", [
    (lambda ls: [ls[0]] + ls[2:3] + ls[4:], None),  # header field missing (gate length)
    (lambda ls: [x.replace("Number of gates:\t20", "Number of gates:\ttwenty") for x in ls], 3),
    (lambda ls: ls[:18] + ["  0 0.4969 0.9x3586 -9.242015E-7"] + ls[19:], 19),
    (lambda ls: ls[:19] + ls[20:], 20),  # gate 1 missing: gate 2 found where 1 expected
    (lambda ls: ls[:17] + ["0.13843889 255.00  -0.00"] + ls[18:], 18),
    (lambda ls: ls[:-5], None),  # last ray cut short
    (lambda ls: [x.replace("No. of rays in file:\t4", "No. of rays in file:\t6") for x in ls], None),
    (lambda ls: [x for x in ls if not x.startswith("****")], None),
])
def test_malformed_files_refused_in_one_line(tmp_path, edit, where):
    bad = _corrupt(tmp_path, RHI, edit)
    with pytest.raises(ValueError) as err:
        read_hpl(bad)
    msg = str(err.value)
    assert "\n" not in msg and str(bad) in msg
    if where is not None:
        assert f"line {where}:" in msg, msg


def test_unknown_gate_centre_formula_refused(tmp_path):
    bad = _corrupt(tmp_path, RHI, lambda ls: [x.replace("(range gate x 3)", "(range gate ^ 2)")
                                              for x in ls])
    with pytest.raises(ValueError, match=r"line 12: gate-centre formula") as err:
        read_hpl(bad)
    assert "\n" not in str(err.value) and str(bad) in str(err.value)


def test_empty_and_missing_files(tmp_path):
    (tmp_path / "e.hpl").write_text("")
    with pytest.raises(ValueError, match="e.hpl"):
        read_hpl(tmp_path / "e.hpl")
    with pytest.raises(FileNotFoundError):
        read_hpl(tmp_path / "none.hpl")
