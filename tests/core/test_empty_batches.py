"""Every batched entry point given a batch of 0 records returns empty results: every field
with the batch axis of length 0, the other axes and the dtypes as for a batch of records
(issue 37: `invert` raised ZeroDivisionError from inside `jnp.reshape`)."""

import dataclasses

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.workflows.joint_records import correct_records_joint
from lidarjax.workflows.records import correct_records, load_records

from .. import _campaign as cp
from ..helpers import windcube_file

HEIGHTS = np.array([40.0, 54.0, 74.0])
DIRECTIONS = np.arange(0.0, 360.0, 30.0)
ALPHAS = (0.0, 0.1, 0.2)


def _dbs(los):
    s = 2.0 * np.sin(np.deg2rad(cp.CONE))
    return np.stack([(los[..., 1] - los[..., 3]) / s, (los[..., 0] - los[..., 2]) / s,
                     los[..., 4]], -1)


def _table(alpha):
    resp, vel, beams = cp.table_runs(DIRECTIONS, HEIGHTS, alpha, 100.0)
    return lj.ResponseTable(DIRECTIONS, resp, beam_velocity=vel, beam_vectors=beams,
                            heights=HEIGHTS, reconstructed=_dbs(resp))


@pytest.fixture(scope="module")
def table():
    return _table(0.14)


@pytest.fixture(scope="module")
def profile_table():
    return lj.ProfileTable("alpha", np.array(ALPHAS), [_table(a) for a in ALPHAS])


#: trailing shapes of a `JointInversion`'s fields beyond the batch axes (h: heights)
JOINT = {"correlation": (3, 3), "height_speed": ("h",), "height_speed_std": ("h",)}
INTS = {"n_beams", "num_steps", "flags"}


def _assert_empty(out, batch, dtype, trailing):
    """Every field of `out` (an `Inversion` or `JointInversion`) has shape ``batch +
    trailing(name)`` and the dtype of its kind: `dtype` for values, bool for `converged`,
    integers for counts, flags and the solver's result code."""
    for name in out.__dataclass_fields__:
        value = getattr(out, name)
        if name == "result":
            value = value._value
            assert np.issubdtype(value.dtype, np.integer), name
        elif name == "converged":
            assert value.dtype == bool
        elif name in INTS:
            assert np.issubdtype(value.dtype, np.integer), name
        else:
            assert value.dtype == dtype, name
        want = tuple(HEIGHTS.size if d == "h" else d for d in trailing(name))
        assert value.shape == batch + want, (name, value.shape)


@pytest.mark.parametrize(("batch", "dtype", "batch_size"), [
    ((0,), np.float64, None), ((2, 0), np.float64, 4), ((0, 3), np.float32, None)])
def test_invert_of_no_records_is_empty(table, batch, dtype, batch_size):
    los = np.zeros(batch + (HEIGHTS.size, 5), dtype)
    out = lj.invert(table, los, batch_size=batch_size)
    _assert_empty(out, batch, dtype, lambda name: (HEIGHTS.size,))


def test_invert_reconstructed_and_joint_of_no_records_are_empty(table, profile_table):
    none = np.zeros((0, HEIGHTS.size))
    _assert_empty(lj.invert_reconstructed(table, none, none), (0,), np.float64,
                  lambda name: (HEIGHTS.size,))
    joint = lambda name: JOINT.get(name, ())  # noqa: E731
    _assert_empty(lj.invert_joint(profile_table, np.zeros((0, HEIGHTS.size, 5))), (0,),
                  np.float64, joint)
    _assert_empty(lj.invert_joint_reconstructed(profile_table, none, none), (0,), np.float64,
                  joint)


@pytest.mark.filterwarnings("ignore:calibrate. the table has no beam_gradient")
def test_calibrate_of_no_records_estimates_nothing(table):
    c = lj.calibrate(np.zeros((0, HEIGHTS.size, 5)), table, wrt=("pitch", "roll"))
    assert int(c.n_records) == 0 and int(c.n_problems) == 0
    assert np.all(np.isnan(np.asarray(c.offset))) and np.all(np.isnan(np.asarray(c.std)))
    assert not np.any(np.asarray(c.identifiable)) and not c.converged
    assert np.asarray(c.offset).dtype == np.float64


def _no_records(rec):
    """`rec` (a loaded `RecordSet`) cut to its first 0 records."""
    n = rec.time.size
    return dataclasses.replace(rec, **{
        k: v[:0] for k, v in vars(rec).items()
        if isinstance(v, np.ndarray) and v.ndim and v.shape[0] == n})


@pytest.mark.parametrize("name", ["wls7_abc_2020_10_07__00_10_00.sta",
                                  "WLS866-104_2024_08_02__23_44_55.rtd"])
def test_correct_records_of_no_records_is_empty(table, profile_table, name):
    path = windcube_file(name)
    rec = load_records(path)
    empty = _no_records(rec)
    assert empty.time.size == 0 and rec.time.size > 0
    joint = [] if rec.kind == "rtd" else [  # (the .rtd shares fewer heights with the table)
        correct_records_joint(profile_table, path, records=empty).corrected]
    for c in [correct_records(table, path, records=empty)] + joint:
        h = np.intersect1d(rec.heights, HEIGHTS).size
        assert c.time.shape == (0,) and c.heights.size == h
        for k in ("speed", "direction", "speed_std", "direction_std", "noise", "converged",
                  "flags", "measured_speed", "measured_direction", "record_flags"):
            assert np.asarray(getattr(c, k)).shape == (0, h), k
        assert c.converged.dtype == bool and np.issubdtype(c.flags.dtype, np.integer)
