"""Response-table files (`lidarjax.io.save_table`, `lidarjax.io.load_table`)."""

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import load_table, save_table


def table(dtype=np.float64):
    d = np.arange(0.0, 360.0, 30.0)
    rng = np.random.default_rng(1)
    resp = rng.normal(size=(d.size, 2, 5)).astype(dtype)
    return lj.ResponseTable(d.astype(dtype), resp)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_round_trip_keeps_values_dtype_and_metadata(tmp_path, dtype):
    t = table(dtype)
    path = save_table(tmp_path / "t.npz", t, metadata={"scan": "windcube_v2", "heights_m": [40, 80]})
    back, meta = load_table(path, return_metadata=True)
    assert np.asarray(back.response).dtype == dtype
    np.testing.assert_array_equal(np.asarray(back.response), np.asarray(t.response))
    np.testing.assert_array_equal(np.asarray(back.directions), np.asarray(t.directions))
    assert meta["scan"] == "windcube_v2" and meta["heights_m"] == [40, 80]
    assert [p.name for p in tmp_path.iterdir()] == ["t.npz"]  # atomic: no temporary left


def test_not_a_table_is_one_line_naming_the_file(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_text("not numpy")
    with pytest.raises(ValueError, match="bad.npz: not a NumPy .npz table file"):
        load_table(bad)
    with pytest.raises(FileNotFoundError, match="response table not found"):
        load_table(tmp_path / "missing.npz")


def test_the_instrument_travels_with_the_table(tmp_path):
    """A table built through the Python API knows its scan and installation; the file keeps
    it; explicit metadata wins over it."""
    scene = lj.scenes.uniform(10.0, 0.0)
    scan = lj.windcube_v2(15.0)
    mount = lj.Mount([0.0, 0.0, 0.0], epsilon=12.0, pitch=0.4)
    sims = [lj.simulate(lj.scenes.uniform(10.0, d), scan, mount, [40.0, 80.0],
                        u_ref=10.0 * lj.heading(d)) for d in (0.0, 120.0, 240.0)]
    del scene
    t = lj.ResponseTable.from_simulations(sims, mount=mount, scan=scan, probe=lj.PulsedProbe())
    inst = t.instrument
    assert (inst.scan, inst.cone_angle_deg, inst.n_beams, inst.vertical_beam) == \
        ("windcube_v2", 15.0, 5, True)
    assert inst.heights_m == (40.0, 80.0) and inst.epsilon_deg == 12.0
    assert inst.pitch_deg == pytest.approx(0.4) and inst.probe == "pulsed"
    path = save_table(tmp_path / "t.npz", t, metadata={"site": "x", "probe": "PulsedProbe()"})
    back, meta = load_table(path, return_metadata=True)
    assert meta["cone_angle_deg"] == 15.0 and meta["epsilon_deg"] == 12.0
    assert meta["probe"] == "PulsedProbe()" and meta["site"] == "x"
    assert back.instrument.cone_angle_deg == 15.0 and back.instrument.heights_m == (40.0, 80.0)
    assert lj.ResponseTable.from_simulations(sims, mount=mount).instrument is None
