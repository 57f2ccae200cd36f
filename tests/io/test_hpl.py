"""Halo StreamLine `.hpl` files (tests/data/scanning/README.md): every real file at hand
(the committed RHI, the stares and the VAD of ../shared/data/scanning, the VAD cut made
here by its recipe) read and compared value for value with an independent reader, doppy
(actris-cloudnet, its own Rust parser; the `test` extra), every ray kept and grouped into
the header's scans; synthetic files in the real layout (`tests.helpers.write_hpl`) for the
variants no real file here has (midnight, user scans, truncation, an hour of scans);
malformed files refused in one line naming the file and line."""

from __future__ import annotations

import warnings

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import read_hpl

from ..helpers import SCANNING, VAD_SOURCE, scanning_file, vad_cut, write_hpl

RHI = SCANNING / "RHI_77_20260921_000812.hpl"
STARE = "Stare_91_20221214_12.hpl"
CUT = "VAD_194_20210624_170110_cut.hpl (recipe)"
#: Every real .hpl: (name, rays held, header rays per scan, scans, warning or None).
REAL = {
    "Stare_91_20221214_12.hpl": (1, 1, 1, None),
    "Stare_91_20221214_11.hpl": (2, 1, 2, None),
    "Stare_213_20221213_04.hpl": (2, 1, 2, None),
    "Stare_46_20230913_23.hpl": (1, 1, 1, None),  # 3-number ray lines, no final newline
    VAD_SOURCE: (2, 6, 1, "6 rays per scan and the file holds 2 rays"),
    "VAD_194_20210624_170110_cut.hpl": (2, 2, 1, None),  # shared/: header edited (6 -> 2)
    CUT: (2, 6, 1, "6 rays per scan and the file holds 2 rays"),
    RHI.name: (4, 4, 1, None),
}


@pytest.fixture(scope="module")
def cut_folder(tmp_path_factory):
    return tmp_path_factory.mktemp("vad_cut")


def _path(name, folder):
    if name == CUT:
        return vad_cut(folder)
    return RHI if name == RHI.name else scanning_file(name)


def _read(path, expect_warning=None):
    """`read_hpl`, asserting the one-line warning it gives (or that it gives none)."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        scan = read_hpl(path)
    messages = [str(w.message) for w in caught]
    if expect_warning is None:
        assert messages == []
    else:
        assert len(messages) == 1 and expect_warning in messages[0], messages
        assert "\n" not in messages[0] and str(path) in messages[0]
    return scan


def test_the_list_holds_every_real_file():
    """Every .hpl in tests/data/scanning and ../shared/data/scanning is in `REAL`."""
    found = {p.name for p in SCANNING.glob("*.hpl")}
    shared = scanning_file(STARE).parent
    found |= {p.name for p in shared.glob("*.hpl")}
    assert found <= set(REAL), found - set(REAL)


@pytest.mark.parametrize("name", list(REAL))
def test_every_real_file_agrees_with_doppy(name, cut_folder):
    """Header numbers, ray times, angles, Doppler, intensity, beta (and spectral width) of
    every real file equal doppy's reading of it, value for value (both convert the same
    decimal text: bitwise equal), and the rays are grouped into the header's scans."""
    import doppy
    path = _path(name, cut_folder)
    rays, per_scan, scans, warning = REAL[name]
    scan = _read(path, warning)
    ref = doppy.raw.HaloHpl.from_src(path)
    h = ref.header
    assert (scan.n_rays, scan.rays_per_scan, scan.n_scans) == (rays, per_scan, scans)
    np.testing.assert_array_equal(scan.scan, np.arange(rays) // per_scan)
    assert (scan.n_gates, scan.gate_points, scan.pulses_per_ray, scan.rays_per_scan) == (
        h.ngates, h.gate_points, h.pulses_per_ray, h.nrays)
    assert (scan.gate_length, scan.resolution, scan.focus_range) == (
        h.range_gate_length, h.resolution, h.focus_range)
    assert (scan.scan_type, scan.system_id) == (h.scan_type, h.system_id)
    assert scan.instrument_spectral_width == h.instrument_spectral_width
    # doppy keeps the header's start time to the whole second
    assert scan.start_time.astype("datetime64[s]") == h.start_time.astype("datetime64[s]")
    # ray times: doppy truncates hours * 3.6e9 to the microsecond, lidarjax rounds
    lag = (scan.time - ref.time.astype("datetime64[us]")) / np.timedelta64(1, "us")
    assert np.all((lag >= 0) & (lag <= 1)), lag
    np.testing.assert_array_equal(scan.ranges, ref.radial_distance)
    np.testing.assert_array_equal(scan.azimuth, ref.azimuth)
    np.testing.assert_array_equal(scan.elevation, ref.elevation)
    for mine, theirs in ((scan.pitch, ref.pitch), (scan.roll, ref.roll),
                         (scan.spectral_width, ref.spectral_width)):
        assert (mine is None) == (theirs is None)
        if mine is not None:
            np.testing.assert_array_equal(mine, theirs)
    np.testing.assert_array_equal(scan.doppler, ref.radial_velocity)
    np.testing.assert_array_equal(scan.intensity, ref.intensity)
    np.testing.assert_array_equal(scan.beta, ref.beta)


def test_header_fields_and_threshold(cut_folder):
    s = _read(scanning_file(STARE))
    assert (s.n_gates, s.gate_length, s.scan_type, s.system_id) == (250, 48.0, "Stare", "91")
    assert s.start_time == np.datetime64("2022-12-14T12:00:20.64")
    assert s.spectral_width is None
    v = _read(vad_cut(cut_folder), "6 rays per scan")
    assert v.scan_type == "VAD" and v.spectral_width is not None and v.n_gates == 40
    assert (v.n_rays, v.rays_per_scan, v.complete_scans) == (2, 6, 0)
    assert v.instrument_spectral_width == 5.656623  # from the '****' line
    # the ray time is hours after midnight of the start date
    np.testing.assert_allclose((v.time[0] - np.datetime64("2021-06-24")) / np.timedelta64(1, "s"),
                               17.02071944 * 3600, atol=1e-5)
    los = s.radial_velocity(1.02)
    keep = s.intensity >= 1.02
    assert 0 < keep.sum() < keep.size
    np.testing.assert_array_equal(np.isnan(los), ~keep)
    np.testing.assert_array_equal(los[keep], s.doppler[keep])


def test_the_recipe_cut_keeps_its_source_header(cut_folder):
    """The VAD cut made by the recipe: the source's lines, its header's 6 rays per scan,
    40 gates (4,124 bytes; README's sha256)."""
    import hashlib

    cut = vad_cut(cut_folder)
    data = cut.read_bytes()
    assert len(data) == 4124
    assert hashlib.sha256(data).hexdigest() == (
        "e2d769030a0e5f300c9d018a2ae8270edc3d3f39c910cce0f596b64429dedc32")
    assert b"No. of rays in file:\t6\r\n" in data and b"Number of gates:\t40\r\n" in data
    source = _read(scanning_file(VAD_SOURCE), "6 rays per scan")
    v = _read(cut, "6 rays per scan")
    np.testing.assert_array_equal(v.doppler, source.doppler[:, :40])
    np.testing.assert_array_equal(v.time, source.time)


def test_simulated_scan_in_the_real_layout(cut_folder):
    """The VAD file's layout (its rays, gates and times) simulated in a uniform wind: same
    ranges and times, and the LOS of a level instrument are n . V with the file's angles
    (the file's pitch and roll given to the mount tilt the rays, as the instrument is)."""
    v = _read(vad_cut(cut_folder), "6 rays per scan")
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


def _gates(r, g, seed=0):
    return np.round(np.random.default_rng(seed).normal(0.0, 3.0, (r, g)), 4)


def test_midnight_crossed_times_keep_increasing(tmp_path):
    """A stare from 23:59:00 to 00:01:00: decimal hours written modulo 24 (as read by
    doppy, which does not continue them), times one day on after midnight."""
    hours = 23.0 + 59 / 60 + np.arange(5) * 30 / 3600  # 23:59:00 ... 00:01:00
    path = write_hpl(tmp_path / "Stare_99_20240301_23.hpl", hours=hours, azimuth=np.zeros(5),
                     elevation=np.full(5, 90.0), doppler=_gates(5, 6))
    s = _read(path)
    np.testing.assert_allclose(s.decimal_hours, np.round(hours % 24, 8))
    expect = np.datetime64("2024-03-01T23:59:00") + np.arange(5) * np.timedelta64(30, "s")
    # 8 decimals of an hour: 18 us
    assert np.all(np.abs((s.time - expect) / np.timedelta64(1, "us")) <= 18)
    assert np.all(np.diff(s.time) > np.timedelta64(0, "us"))
    assert (s.n_rays, s.n_scans) == (5, 5)
    # a file started just after midnight whose first ray was written just before
    path = write_hpl(tmp_path / "Stare_99_20240302_00.hpl", hours=hours[:3],
                     start="20240302 00:00:00.40", azimuth=np.zeros(3),
                     elevation=np.full(3, 90.0), doppler=_gates(3, 6))
    s = _read(path)
    assert abs((s.time[0] - np.datetime64("2024-03-01T23:59:00")) / np.timedelta64(1, "us")) <= 18
    assert np.all(np.diff(s.time) > np.timedelta64(0, "us"))


def test_user_scan_older_layout_and_no_final_newline(tmp_path):
    """A user scan (waypoints), ray lines of time, azimuth, elevation only, no final
    newline: every value read; doppy agrees."""
    az, el = np.array([10.0, 80.0, 150.0]), np.array([30.0, 45.0, 60.0])
    dop = _gates(3, 4, seed=1)
    path = write_hpl(tmp_path / "User1_99_20240301_120000.hpl", hours=12 + np.arange(3) / 3600,
                     azimuth=az, elevation=el, doppler=dop, scan_type="User file 1 - csm",
                     rays_per_scan=3, pitch_roll=False, newline="\n")
    text = path.read_text().replace("No. of rays in file", "No. of waypoints in file")
    path.write_text(text.rstrip("\n"))
    s = _read(path)
    assert s.scan_type == "User file 1 - csm" and s.pattern().kind == "custom"
    assert s.pitch is None and s.roll is None and s.rays_per_scan == 3
    np.testing.assert_array_equal(s.azimuth, az)
    np.testing.assert_array_equal(s.doppler, dop)
    import doppy
    ref = doppy.raw.HaloHpl.from_src(path)
    np.testing.assert_array_equal(s.doppler, ref.radial_velocity)
    assert ref.pitch is None and ref.header.nwaypoints == 3


def test_repeated_vad_per_scan(tmp_path):
    """An hour of a 6-ray VAD (every 5 minutes, each scan at slightly different azimuths)
    in a wind turning with time: grouped into 12 scans, and `vad_fit` per scan (its own
    angles) gives each scan's wind exactly."""
    n_scan, m, g = 12, 6, 5
    hours = 10.0 + (np.arange(n_scan)[:, None] * 300 + np.arange(m)[None] * 8.0) / 3600
    az = (np.arange(m)[None] * 60.0 + np.arange(n_scan)[:, None] * 1.5) % 360
    el = np.full((n_scan, m), 75.0)
    wind = np.stack([8 * np.sin(np.radians(10 * np.arange(n_scan))),
                     8 * np.cos(np.radians(10 * np.arange(n_scan))), np.full(n_scan, 0.2)], 1)
    n = np.stack([np.cos(np.radians(el)) * np.sin(np.radians(az)),
                  np.cos(np.radians(el)) * np.cos(np.radians(az)), np.sin(np.radians(el))], -1)
    los = np.repeat(np.einsum("smi,si->sm", n, wind)[..., None], g, -1)
    path = write_hpl(tmp_path / "VAD_99_20240301_100000.hpl", hours=hours.ravel(),
                     azimuth=az.ravel(), elevation=el.ravel(), doppler=los.reshape(-1, g),
                     scan_type="VAD", rays_per_scan=m)
    s = _read(path)
    assert (s.n_rays, s.n_scans, s.complete_scans) == (72, 12, 12)
    prof = lj.scanning.vad_fit(s.per_scan(s.radial_velocity()), s.per_scan(s.azimuth),
                               s.per_scan(s.elevation), s.ranges)
    # the file holds 4 decimals of the LOS and 2 of the angles
    np.testing.assert_allclose(np.asarray(prof.velocity), np.repeat(wind[:, None], g, 1), atol=2e-3)
    # per-scan angles are differentiable: d(sum u)/d(azimuth) against central differences
    import jax

    def total_u(azimuth):
        return lj.scanning.vad_fit(s.per_scan(s.radial_velocity()), azimuth,
                                   s.per_scan(s.elevation), s.ranges).velocity[..., 0].sum()

    az0 = s.per_scan(s.azimuth)
    grad = np.asarray(jax.grad(total_u)(az0))
    assert np.isfinite(grad).all() and np.abs(grad[5]).max() > 0
    bump = np.zeros_like(az0)
    bump[5, 2] = 1e-5
    fd = (float(total_u(az0 + bump)) - float(total_u(az0 - bump))) / 2e-5
    assert grad[5, 2] == pytest.approx(fd, rel=1e-6, abs=1e-9)
    assert s.rays(s.scan == 3).n_rays == 6
    np.testing.assert_array_equal(s.rays(s.scan == 3).azimuth, az[3])
    with pytest.raises(ValueError, match="one row per ray"):
        s.per_scan(s.azimuth[:5])


def test_an_hour_of_stare_pattern_times(tmp_path):
    """A one-hour stare (header 1 ray per scan, 360 rays every 10 s): 360 scans, the
    pattern holds every ray, each ending at its own time."""
    hours = 14.0 + np.arange(360) * 10.0 / 3600
    path = write_hpl(tmp_path / "Stare_99_20240301_14.hpl", hours=hours, azimuth=np.zeros(360),
                     elevation=np.full(360, 90.0), doppler=_gates(360, 3))
    s = _read(path)
    assert (s.n_rays, s.n_scans) == (360, 360)
    p = s.pattern()
    end = np.asarray(p.ray_start) + s.accumulation()
    np.testing.assert_allclose(end - end[0], np.arange(360) * 10.0, atol=2e-5)  # 18 us
    assert float(p.period) == pytest.approx(3590.0 + s.accumulation(), abs=2e-5)


def _corrupt(tmp_path, path, fn, end="\n"):
    lines = path.read_text().splitlines()
    out = tmp_path / path.name
    out.write_text("\n".join(fn(lines)) + end)
    return out


@pytest.mark.parametrize("edit, end, line, what", [
    (lambda ls: ls[:-5], "\n", 96, "ends after 15 of 20 gates"),  # last ray cut short
    (lambda ls: ls[:-1] + [" 19 18.1165 1.03"], "\n", 101, "expected a gate line"),
    (lambda ls: ls[:-1] + [" 19 18.1165 1.037231 2.10259"], "", 101, "last number cut"),
    (lambda ls: ls[:-1] + [" 19 18.1165 1.037231 2.102597E-"], "", 101, "expected a gate line"),
    (lambda ls: ls[:81], "\n", 81, "ends after 0 of 20 gates"),  # a ray line alone at the end
    (lambda ls: ls[:80] + ["0.1408"], "", 81, "expected a ray line"),
])
def test_truncated_files_keep_their_complete_rays(tmp_path, edit, end, line, what):
    cut = _corrupt(tmp_path, RHI, edit, end)
    s = _read(cut, f"line {line}: truncated file")
    full = read_hpl(RHI)
    assert s.n_rays == 3
    np.testing.assert_array_equal(s.doppler, full.doppler[:3])
    with pytest.warns(UserWarning, match=what):
        read_hpl(cut)


@pytest.mark.parametrize("end", ["\n", "\r\n", "\r", "\n  "])
def test_a_final_line_end_keeps_a_last_line_of_fewer_decimals(tmp_path, end):
    """The RHI's last line with its beta written to 5 decimals (the line before has 6):
    ended by a line end it was written whole and all 4 rays are kept, value for value; the
    same line without a final line end may be cut mid-number, and its ray is dropped."""
    last = " 19 0.8026 1.101089  5.70896E-6"

    def edit(ls):
        return ls[:-1] + [last]

    full = read_hpl(RHI)
    s = _read(_corrupt(tmp_path, RHI, edit, end))
    assert s.n_rays == 4
    np.testing.assert_array_equal(s.doppler, full.doppler)
    np.testing.assert_array_equal(s.beta[:, :-1], full.beta[:, :-1])
    np.testing.assert_array_equal(s.beta[:3], full.beta[:3])
    assert s.beta[3, 19] == 5.70896e-6
    s = _read(_corrupt(tmp_path, RHI, edit, ""), "line 101: truncated file")
    assert s.n_rays == 3


def test_whole_files_without_final_newline_and_wrong_counts(tmp_path):
    """No final newline on a complete file: no warning. A header count that the rays held do
    not fill: one warning, every ray kept."""
    s = _read(_corrupt(tmp_path, RHI, lambda ls: ls, ""))
    assert s.n_rays == 4
    bad = _corrupt(tmp_path, RHI, lambda ls: [x.replace("No. of rays in file:\t4",
                                                         "No. of rays in file:\t6") for x in ls])
    s = _read(bad, "6 rays per scan and the file holds 4 rays")
    assert (s.n_rays, s.n_scans, s.complete_scans) == (4, 1, 0)
    s = _read(_corrupt(tmp_path, RHI, lambda ls: [x.replace("No. of rays in file:\t4",
                                                            "No. of rays in file:\t2") for x in ls]))
    assert (s.n_rays, s.n_scans) == (4, 2)
    np.testing.assert_array_equal(s.scan, [0, 0, 1, 1])


@pytest.mark.parametrize("edit, where", [
    (lambda ls: [ls[0]] + ls[2:3] + ls[4:], None),  # header field missing (gate length)
    (lambda ls: [x.replace("Number of gates:\t20", "Number of gates:\ttwenty") for x in ls], 3),
    (lambda ls: ls[:18] + ["  0 0.4969 0.9x3586 -9.242015E-7"] + ls[19:], 19),
    (lambda ls: ls[:19] + ls[20:], 20),  # gate 1 missing: gate 2 found where 1 expected
    (lambda ls: ls[:17] + ["0.13843889 255.00  -0.00"] + ls[18:], 39),  # 3 numbers, then 5
    (lambda ls: ls[:37] + ls[38:], 38),  # ray 1 short of a gate, more rays follow
    (lambda ls: ls[:30] + [""] + ls[30:], 31),  # a blank line inside a ray
    (lambda ls: ls[:22], 22),  # truncated within the first ray: no complete ray
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
