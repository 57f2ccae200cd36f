"""Seed settings.dat: reading, writing, lookup by beta value, and every error message."""

import os

import numpy as np
import pytest

from lidarjax.io import Settings, read_settings, write_settings

# Table 2 of the seed report (rows 0..330 every 30 degrees), tab separated as in the seed.
SEED_ROWS = [
    (0, 3.9316, 3.4358, 0.355),
    (30, 3.9235, 3.4343, 0.355),
    (60, 3.929, 3.9255, 0.355),
    (90, 3.7933, 3.9954, 0.355),
    (120, 3.5076, 3.9197, 0.355),
    (150, 3.5076, 3.9197, 0.355),
    (180, 3.15, 3.705, 0.355),
    (210, 3.2308, 3.4255, 0.355),
    (240, 3.2303, 3.2861, 0.355),
    (270, 3.3691, 3.1432, 0.355),
    (300, 3.6541, 3.1466, 0.355),
    (330, 3.9358, 3.1483, 0.355),
]
SEED_HEADER = "zone\tverbose\theight\tnh\tgamma\tbeta\tpsi\tepsilon\n"
SEED_VALUES = "2\t0\t1.0\t50\t0.0\t330.0\t180.0\t21.0\n"


def seed_text(values=SEED_VALUES, rows=SEED_ROWS, header=SEED_HEADER):
    body = "".join("\t".join(str(v) for v in r) + "\n" for r in rows)
    return header + values + body


def write(tmp_path, text, name="settings.dat"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_seed_example(tmp_path):
    s = read_settings(write(tmp_path, seed_text()))
    assert (s.zone, s.verbose, s.height, s.nh) == (2, 0, 1.0, 50)
    assert (s.gamma, s.beta, s.psi, s.epsilon) == (0.0, 330.0, 180.0, 21.0)
    assert s.header == ("zone", "verbose", "height", "nh", "gamma", "beta", "psi", "epsilon")
    assert s.betas.shape == (12,) and s.locations.shape == (12, 3)
    np.testing.assert_array_equal(s.location(), [3.9358, 3.1483, 0.355])
    np.testing.assert_array_equal(s.location(60), [3.929, 3.9255, 0.355])
    # modulo 360 and within the tolerance
    np.testing.assert_array_equal(s.location(-30), s.location(330))
    np.testing.assert_array_equal(s.location(720 + 90 + 5e-7), [3.7933, 3.9954, 0.355])
    h = s.heights()
    assert h.dtype == np.float64 and h.shape == (50,)
    np.testing.assert_allclose(h, np.arange(1, 51) * 1.0 / 50, rtol=0, atol=0)
    assert h[0] == 0.02 and h[-1] == 1.0


def test_arrays_read_only(tmp_path):
    s = read_settings(write(tmp_path, seed_text()))
    with pytest.raises(ValueError):
        s.locations[0, 0] = 1.0
    loc = s.location(0)
    loc[0] = 99.0  # a copy, the settings are unchanged
    assert s.location(0)[0] == 3.9316


def test_lookup_by_value_any_spacing_any_order(tmp_path):
    # 16 sectors of 22.5 degrees, rows shuffled: the C code's "skip beta/30 rows" breaks.
    betas = np.arange(16) * 22.5
    rng = np.random.default_rng(0)
    order = rng.permutation(16)
    rows = [(betas[i], 10.0 + i, 20.0 - i, 0.5) for i in order]
    values = "2 1 120.0 12.0 0.0 67.5 180.0 0.0\n"  # nh written as 12.0, spaces
    s = read_settings(write(tmp_path, seed_text(values, rows)))
    assert s.nh == 12 and s.verbose == 1
    np.testing.assert_array_equal(s.location(), [13.0, 17.0, 0.5])  # 67.5 = betas[3]
    np.testing.assert_array_equal(s.location(337.5), [25.0, 5.0, 0.5])
    np.testing.assert_allclose(s.heights(), np.arange(1, 13) * 10.0)


def test_blank_lines_and_mixed_separators(tmp_path):
    text = "\n zone verbose height nh gamma beta psi epsilon\n\n2\t0 1.0   50 0 30 180 21\n\n" \
           "0 1 2 3\n  30\t4\t5\t6  \n\n"
    s = read_settings(write(tmp_path, text))
    np.testing.assert_array_equal(s.location(), [4.0, 5.0, 6.0])


def test_any_header_words(tmp_path):
    s = read_settings(write(tmp_path, seed_text(header="a b c d e f g h i\n")))
    assert s.header == tuple("abcdefghi")


def test_round_trip(tmp_path):
    s = read_settings(write(tmp_path, seed_text()))
    out = write_settings(tmp_path / "sub.dat", s)
    assert out == tmp_path / "sub.dat"
    t = read_settings(out)
    for name in ("zone", "verbose", "height", "nh", "gamma", "beta", "psi", "epsilon", "header"):
        assert getattr(t, name) == getattr(s, name)
    np.testing.assert_array_equal(t.betas, s.betas)
    np.testing.assert_array_equal(t.locations, s.locations)
    lines = out.read_text().splitlines()
    assert lines[0].split() == list(s.header)
    assert lines[1].split() == ["2", "0", "1", "50", "0", "330", "180", "21"]
    assert lines[2].split() == ["0", "3.9316", "3.4358", "0.355"]
    assert sorted(os.listdir(tmp_path)) == ["settings.dat", "sub.dat"]  # no temp files left


def test_round_trip_constructed(tmp_path):
    s = Settings(zone=7, verbose=1, height=200.0, nh=40, gamma=1.25, beta=22.5, psi=90.0,
                 epsilon=-3.0, betas=np.array([0.0, 22.5]),
                 locations=np.array([[1.0, 2.0, 3.0], [1.0 / 3.0, 2e-7, 1e5]]))
    t = read_settings(write_settings(tmp_path / "s.dat", s))
    np.testing.assert_array_equal(t.locations, s.locations)  # shortest repr is exact
    assert (t.gamma, t.beta, t.epsilon) == (1.25, 22.5, -3.0)
    assert t.source == str(tmp_path / "s.dat") and s.source is None


def test_missing_file(tmp_path):
    path = tmp_path / "nowhere" / "settings.dat"
    with pytest.raises(FileNotFoundError, match="settings file not found: .*nowhere"):
        read_settings(path)


@pytest.mark.parametrize(
    ("values", "rows", "line", "fragment"),
    [
        ("2 0 1.0 50.5 0 330 180 21\n", SEED_ROWS, 2,
         "nh: expected a positive integer, found '50.5'"),
        ("2 0 1.0 0 0 330 180 21\n", SEED_ROWS, 2, "nh: expected a positive integer, found '0'"),
        ("2 0 1.0 -5 0 330 180 21\n", SEED_ROWS, 2, "nh: expected a positive integer"),
        ("2 0 1.0 abc 0 330 180 21\n", SEED_ROWS, 2, "nh: expected a number, found 'abc'"),
        ("2 0 1.0 50 0 330 180\n", SEED_ROWS, 2, "expected 8 values"),
        ("2.5 0 1.0 50 0 330 180 21\n", SEED_ROWS, 2, "zone: expected an integer"),
        ("2 3 1.0 50 0 330 180 21\n", SEED_ROWS, 2, "verbose: expected 0 or 1, found '3'"),
        ("2 0 -1.0 50 0 330 180 21\n", SEED_ROWS, 2, "height: expected a length > 0 m"),
        ("2 0 1.0 50 0 nan 180 21\n", SEED_ROWS, 2, "beta: expected a finite number"),
        (SEED_VALUES, [(0, 1, 2, 3), (30, 1, "y?", 3)], 4, "y: expected a number, found 'y?'"),
        (SEED_VALUES, [(0, 1, 2, 3), (30, 1, 2)], 4, "expected 4 fields 'beta x y z', found 3"),
        (SEED_VALUES, [(0, 1, 2, 3), (30, 1, 2, 3, 4)], 4,
         "expected 4 fields 'beta x y z', found 5"),
    ],
)
def test_malformed_values(tmp_path, values, rows, line, fragment):
    path = write(tmp_path, seed_text(values, rows))
    with pytest.raises(ValueError) as err:
        read_settings(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}, line {line}: "), msg
    assert fragment in msg, msg


def test_missing_row_for_beta(tmp_path):
    path = write(tmp_path, seed_text("2 0 1.0 50 0 45 180 21\n", SEED_ROWS[:3]))
    with pytest.raises(ValueError) as err:
        read_settings(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}, line 2: no location row for the beta of this line (45 degrees)")
    assert "rows exist for betas 0, 30, 60" in msg


def test_location_of_absent_beta(tmp_path):
    path = write(tmp_path, seed_text(rows=SEED_ROWS))
    s = read_settings(path)
    with pytest.raises(ValueError, match=r"no location row for beta = 15 degrees; rows exist for "
                                         r"betas 0, 30, 60, 90, 120, 150, 180, 210, 240, 270, "
                                         r"300, 330"):
        s.location(15)
    with pytest.raises(ValueError, match="settings.dat: no location row for beta = 22.5"):
        s.location(22.5)


def test_duplicate_beta(tmp_path):
    rows = [(0, 1, 2, 3), (330, 4, 5, 6), (360, 7, 8, 9)]  # 360 is 0 again
    path = write(tmp_path, seed_text(rows=rows))
    with pytest.raises(ValueError) as err:
        read_settings(path)
    msg = str(err.value)
    assert msg.startswith(f"{path}, line 5: duplicate location row for beta 360")
    assert "already given on line 3" in msg


def test_header_missing(tmp_path):
    path = write(tmp_path, SEED_VALUES + "0 1 2 3\n330 1 2 3\n")
    with pytest.raises(ValueError, match=r"line 1: expected the header line of 8 words \(zone "
                                         r"verbose height nh gamma beta psi epsilon\)"):
        read_settings(path)


@pytest.mark.parametrize(
    ("text", "fragment"),
    [
        ("", "empty file"),
        ("\n\n", "empty file"),
        (SEED_HEADER, "expected a values line after the header"),
        (SEED_HEADER + SEED_VALUES, "expected location rows 'beta x y z'"),
    ],
)
def test_truncated(tmp_path, text, fragment):
    path = write(tmp_path, text)
    with pytest.raises(ValueError, match=fragment) as err:
        read_settings(path)
    assert str(err.value).startswith(str(path))


def test_constructor_validation():
    good = dict(zone=1, verbose=0, height=1.0, nh=3, gamma=0.0, beta=0.0, psi=0.0, epsilon=0.0,
                betas=np.array([0.0]), locations=np.zeros((1, 3)))
    assert Settings(**good).nh == 3
    with pytest.raises(ValueError, match="nh must be a positive integer"):
        Settings(**{**good, "nh": 2.5})
    with pytest.raises(ValueError, match="verbose must be 0 or 1"):
        Settings(**{**good, "verbose": 2})
    with pytest.raises(ValueError, match=r"locations must have shape \(s, 3\) = \(1, 3\)"):
        Settings(**{**good, "locations": np.zeros((2, 3))})
    with pytest.raises(ValueError, match="duplicate location rows for beta 10 and 370"):
        Settings(**{**good, "betas": np.array([10.0, 370.0]), "locations": np.zeros((2, 3))})
    with pytest.raises(ValueError, match="at least one location row"):
        Settings(**{**good, "betas": np.zeros(0), "locations": np.zeros((0, 3))})
