"""invert / invert_reconstructed: recovery, convergence order, robustness, noise, gradients.

Every call goes through `solve`, which pads the records to a fixed count so that one
compiled solver serves the whole module (float64, 4 heights, 5 beams, 12 or 24 sectors).
"""

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import lidarjax as lj
from lidarjax.flags import InverseFlag

from .. import sites

R = 64  # records per compiled call


def solve(table, los, **kwargs):
    """`lj.invert` of `los` padded with NaN records to `R` (one compiled solver); padding
    and cropping in numpy outside a trace (eager jax slices would compile once per length)."""
    if isinstance(los, jax.core.Tracer):
        n = los.shape[0]
        pad = jnp.full((R - n,) + los.shape[1:], jnp.nan, los.dtype)
        out = lj.invert(table, jnp.concatenate([los, pad]), **kwargs)
        return jax.tree_util.tree_map(lambda a: a[:n], out)
    los = np.asarray(los)
    n = los.shape[0]
    pad = np.full((R - n,) + los.shape[1:], np.nan, los.dtype)
    out = lj.invert(table, np.concatenate([los, pad]), **kwargs)
    return jax.tree_util.tree_map(lambda a: np.asarray(a)[:n], out)


def _truth(cfd_directions, speeds):
    sims = sites.records(cfd_directions, speeds)
    return sims, np.asarray(sims.free_speed), np.asarray(sims.free_direction)


def _errors(inv, speed, direction):
    es = np.abs(np.asarray(inv.speed) / speed[:, None] - 1.0)
    ed = np.abs(np.asarray(lj.wrap180(inv.direction - direction[:, None])))
    return es, ed


@pytest.fixture(scope="module")
def table():
    return sites.table(30.0)


@pytest.fixture(scope="module")
def random_records():
    rng = np.random.default_rng(1)
    return _truth(rng.uniform(0.0, 360.0, R), rng.uniform(2.0, 20.0, R))


def test_table_directions_recovered_to_1e_8(table):
    cfd = np.arange(0.0, 360.0, 30.0)
    speeds = np.linspace(0.5, 25.0, cfd.size)
    sims, speed, direction = _truth(cfd, speeds)
    inv = solve(table, sims.los)
    es, ed = _errors(inv, speed, direction)
    assert np.all(inv.converged)
    assert es.max() < 1e-8 and ed.max() < 1e-8
    assert np.all(inv.num_steps <= 2)
    assert np.all(inv.flags == 0) and np.all(inv.result == optx.RESULTS.successful)


def test_other_directions_far_better_than_uncorrected_at_spline_order(table, random_records):
    sims, speed, direction = random_records
    inv30 = solve(table, sims.los)
    inv15 = solve(sites.table(15.0), sims.los)
    es30, ed30 = _errors(inv30, speed, direction)
    es15, ed15 = _errors(inv15, speed, direction)
    unc_s = np.abs(np.asarray(sims.lidar_speed) / speed[:, None] - 1.0)
    unc_d = np.abs(np.asarray(lj.wrap180(sims.lidar_direction - direction[:, None])))
    assert np.all(inv30.converged) and np.all(inv15.converged)
    # per height, the mean inverse error is far below the uncorrected one (15-degree
    # sectors: over 500 times; 30-degree sectors: over 50 times)
    assert np.all(es15.mean(0) * 500 < unc_s.mean(0)), (es15.mean(0), unc_s.mean(0))
    assert np.all(ed15.mean(0) * 500 < unc_d.mean(0)), (ed15.mean(0), unc_d.mean(0))
    assert np.all(es30.mean(0) * 50 < unc_s.mean(0)), (es30.mean(0), unc_s.mean(0))
    assert np.all(ed30.mean(0) * 50 < unc_d.mean(0)), (ed30.mean(0), unc_d.mean(0))
    # halving the sector spacing divides the error by about 2**4
    order_s = np.log2(es30.max() / es15.max())
    order_d = np.log2(ed30.max() / ed15.max())
    assert order_s > 3.5 and order_d > 3.5, (order_s, order_d)


def test_start_at_359_converges_to_1_degree():
    table = sites.table(30.0, first=-sites.EPSILON - 1.0)  # knots at 359, 29, 59, ... (north)
    assert float(table.directions[-1]) == pytest.approx(359.0)
    sims, speed, direction = _truth([1.0 - sites.EPSILON, 0.2 - sites.EPSILON], [8.0, 8.0])
    inv = solve(table, sims.los)
    assert np.all(inv.converged)
    np.testing.assert_allclose(inv.direction[0], 1.0, atol=1e-3)
    np.testing.assert_allclose(inv.direction[1], 0.2, atol=1e-3)
    assert np.all((inv.direction >= 0) & (inv.direction < 360))
    assert np.all(inv.num_steps <= 6)


def test_bad_records_are_contained(table):
    sims, _, truth = _truth([1.0, 200.0], [8.0, 12.0])
    clean = np.asarray(sims.los[0])
    other = np.asarray(sims.los[1])
    cases = {
        "zero": np.zeros_like(clean),
        "miss1": np.where(np.arange(5) == 1, np.nan, clean),
        "miss2": np.where(np.isin(np.arange(5), [1, 3]), np.nan, clean),
        "miss3": np.where(np.arange(5) < 3, np.nan, clean),
        "wild": clean + np.where(np.arange(5) == 2, 50.0, 0.0),
        "equal": np.full_like(clean, 5.0),
        "all_nan": np.full_like(clean, np.nan),
        "inf": np.where(np.arange(5) == 0, np.inf, clean),
        "huge": clean * 1e6,
        "tiny": clean * 1e-9,
    }
    batch = np.stack([other] + [x for c in cases.values() for x in (c, other)])
    inv = solve(table, batch, max_steps=32)
    alone = solve(table, other[None])
    # neighbours are bit-for-bit what they are alone
    for i in range(0, batch.shape[0], 2):
        np.testing.assert_array_equal(inv.speed[i], alone.speed[0])
        np.testing.assert_array_equal(inv.direction[i], alone.direction[0])
    assert np.all(inv.num_steps <= 32)
    res = {k: jax.tree_util.tree_map(lambda a, i=i: a[2 * i + 1], inv) for i, k in enumerate(cases)}
    # finite answer with honest (finite or inf) uncertainty, or NaN with converged=False
    for k, r in res.items():
        ok = np.asarray(r.converged)
        assert np.all(np.isfinite(r.speed[ok])), k
        assert np.all(~np.isnan(r.speed_std[ok])), k
        assert np.all(np.isnan(r.speed[~ok])), k
    z = res["zero"]
    assert np.all(z.converged) and np.all(z.speed == 0) and np.all(np.isnan(z.direction))
    assert np.all(z.flags & InverseFlag.CALM) and np.all(np.isinf(z.direction_std))
    for k in ("miss1", "miss2", "huge", "tiny"):
        scale = {"huge": 1e6, "tiny": 1e-9}.get(k, 1.0)
        assert np.all(res[k].converged), k
        np.testing.assert_allclose(res[k].speed, 8.0 * scale, rtol=1e-3)
        np.testing.assert_allclose(lj.wrap180(res[k].direction - truth[0]), 0.0, atol=0.05)
    assert np.all(res["miss2"].n_beams == 3)
    for k in ("miss3", "all_nan"):
        assert not np.any(res[k].converged)
        assert np.all(res[k].flags & InverseFlag.TOO_FEW_BEAMS), k
    assert np.all(res["inf"].converged) and np.all(res["inf"].n_beams == 4)
    # a wild beam or an impossible pattern is fitted with an honestly large uncertainty
    for k in ("wild", "equal"):
        r = res[k]
        assert np.all(r.converged), k
        assert np.all(r.speed_std > 1.0), (k, r.speed_std)
        assert np.all(r.residual_rms > 1.0), k


def test_weights_and_missing_beams_agree(table, random_records):
    sims, _, _ = random_records
    los = np.asarray(sims.los[:8])
    w = np.ones(5)
    w[2] = 0.0
    a = solve(table, los, weights=w)
    b = solve(table, np.where(np.arange(5) == 2, np.nan, los))
    np.testing.assert_allclose(a.speed, b.speed, rtol=1e-12)
    np.testing.assert_allclose(a.direction, b.direction, rtol=1e-12)
    # scaling all weights by 4 changes nothing but the given-noise uncertainty (halved)
    c = solve(table, los, weights=4.0, noise=0.1)
    d = solve(table, los, noise=0.1)
    np.testing.assert_allclose(c.speed, d.speed, rtol=1e-10)
    np.testing.assert_allclose(c.speed_std, d.speed_std / 2, rtol=1e-10)


def test_noise_bias_and_uncertainty_match_monte_carlo(table):
    sigma = 0.1
    sims, speed, direction = _truth([77.0], [8.0])
    rng = np.random.default_rng(2)
    n_chunks = 15
    speeds, dirs, sstd, dstd, noise = [], [], [], [], []
    for _ in range(n_chunks):
        los = np.asarray(sims.los) + sigma * rng.standard_normal((R,) + sims.los.shape[1:])
        given = solve(table, los, noise=sigma)
        est = solve(table, los)
        assert np.all(given.converged)
        speeds.append(given.speed)
        dirs.append(given.direction)
        sstd.append(given.speed_std)
        dstd.append(given.direction_std)
        noise.append(est.noise)
    speeds, dirs, sstd, dstd, noise = (np.concatenate(a) for a in (speeds, dirs, sstd, dstd, noise))
    n = speeds.shape[0]
    err_s = speeds - speed[0]
    err_d = np.asarray(lj.wrap180(dirs - direction[0]))
    # bias near zero: within 4 standard errors
    assert np.all(np.abs(err_s.mean(0)) < 4 * err_s.std(0) / np.sqrt(n))
    assert np.all(np.abs(err_d.mean(0)) < 4 * err_d.std(0) / np.sqrt(n))
    # predicted standard deviations match the Monte Carlo spread within 10 %
    np.testing.assert_allclose(sstd.mean(0), err_s.std(0), rtol=0.1)
    np.testing.assert_allclose(dstd.mean(0), err_d.std(0), rtol=0.1)
    # 95 % intervals cover about 95 %
    cover = np.mean(np.abs(err_s) < 1.96 * sstd)
    assert 0.93 < cover < 0.97, cover
    # the residual estimate of the noise is unbiased in variance (3 spare beams)
    np.testing.assert_allclose(np.mean(noise**2), sigma**2, rtol=0.1)


def test_gradients_match_finite_differences(table, random_records):
    sims, _, _ = random_records
    los = np.asarray(sims.los[:4])

    def outputs(x):
        inv = solve(table, x)
        return jnp.stack([inv.speed[0], inv.direction[0]])  # (2, h)

    # one compiled program (an eager jacrev would compile every operation of its linearisation)
    jac = np.asarray(jax.jit(jax.jacrev(outputs))(jnp.asarray(los)))  # (2, h, 4, h, b)
    eps = 1e-6
    for b in range(5):
        for h in (0, 3):
            dp, dm = los.copy(), los.copy()
            dp[0, h, b] += eps
            dm[0, h, b] -= eps
            fd = (np.asarray(outputs(dp)) - np.asarray(outputs(dm))) / (2 * eps)
            np.testing.assert_allclose(jac[:, :, 0, h, b], fd, rtol=1e-5, atol=1e-7)
    # only the record's own LOS at the same height matter
    assert np.all(jac[:, :, 1:] == 0)
    assert np.all(jac[:, 0, 0, 1:] == 0)


def test_float32_in_float32_out_and_chunked_batches(table, random_records):
    sims, speed, direction = random_records
    los32 = np.asarray(sims.los, np.float32)
    # 64 records in batches of 24 records (96 problems): three batches, the last one padded
    inv = solve(table, los32, batch_size=96, noise=0.1)
    assert inv.speed.dtype == jnp.float32 and inv.speed_std.dtype == jnp.float32
    assert np.all(inv.converged)
    ref = solve(table, np.asarray(sims.los), noise=0.1)
    np.testing.assert_allclose(inv.speed, ref.speed, rtol=2e-5)
    np.testing.assert_allclose(lj.wrap180(inv.direction - ref.direction), 0.0, atol=2e-3)
    np.testing.assert_allclose(inv.speed_std, ref.speed_std, rtol=1e-3)


def reconstructed(table, speed, direction, **kwargs):
    """`invert_reconstructed` padded to 360 records: the shape `correction_rose` compiles."""
    n = speed.shape[0]
    pad = lambda a: np.concatenate([a, np.ones((360 - n,) + a.shape[1:], a.dtype)])  # noqa: E731
    out = lj.invert_reconstructed(table, pad(np.asarray(speed)), pad(np.asarray(direction)),
                                  **kwargs)
    return jax.tree_util.tree_map(lambda a: np.asarray(a)[:n], out)


def test_invert_reconstructed(table, random_records):
    sims, speed, direction = random_records
    inv = reconstructed(table, sims.lidar_speed, sims.lidar_direction)
    es, ed = _errors(inv, speed, direction)
    unc = np.abs(np.asarray(sims.lidar_speed) / speed[:, None] - 1.0)
    assert np.all(inv.converged)
    assert np.all(es.mean(0) * 100 < unc.mean(0))
    assert np.all(ed < 0.05)
    # two equations, two unknowns: no spare for a noise estimate unless one is given
    assert np.all(inv.flags & InverseFlag.NO_NOISE_ESTIMATE) and np.all(np.isnan(inv.speed_std))
    # calm, and a direction missing for a positive speed
    s = np.array(sims.lidar_speed[:R])
    d = np.array(sims.lidar_direction[:R])
    s[0] = 0.0
    d[0] = np.nan
    d[1, 2] = np.nan
    bad = reconstructed(table, s, d, noise=0.05)
    assert np.all(bad.converged[0]) and np.all(bad.speed[0] == 0)
    assert not bad.converged[1, 2] and np.isnan(bad.speed[1, 2])
    np.testing.assert_allclose(bad.speed[2:], inv.speed[2:], rtol=1e-12)
    assert np.all(np.isfinite(bad.speed_std[2:]))


def test_validation(table):
    good = np.zeros((3, table.n_heights, table.n_beams))
    with pytest.raises(ValueError, match=r"\(h, b\) = \(4, 5\)"):
        lj.invert(table, good[..., :4])
    with pytest.raises(ValueError, match=r"\(h, b\)"):
        lj.invert(table, good[0, 0])
    with pytest.raises(ValueError, match="weights"):
        lj.invert(table, good, weights=np.ones(3))
    with pytest.raises(ValueError, match="nonnegative"):
        lj.invert(table, good, weights=-np.ones(5))
    with pytest.raises(ValueError, match="noise"):
        lj.invert(table, good, noise=0.0)
    with pytest.raises(ValueError, match="min_beams"):
        lj.invert(table, good, min_beams=1)
    with pytest.raises(ValueError, match="ResponseTable"):
        lj.invert("table", good)
    with pytest.raises(ValueError, match=r"\(\.\.\., h\)"):
        lj.invert_reconstructed(table, np.ones(3), np.ones(3))
    bare = lj.ResponseTable(table.directions, table.response)
    with pytest.raises(ValueError, match="reconstructed"):
        lj.invert_reconstructed(bare, np.ones(4), np.ones(4))


def _distorted_table(seed):
    """A Windcube-like table whose response is far from a first harmonic of direction."""
    rng = np.random.default_rng(seed)
    d = np.sort(rng.choice(np.arange(0.0, 360.0, 5.0), size=24, replace=False))
    r = np.deg2rad(d)[:, None, None]
    az = np.deg2rad(np.array([0.0, 90.0, 180.0, 270.0, 0.0]))
    cone = np.deg2rad(np.array([28.0, 28.0, 28.0, 28.0, 0.0]))
    homogeneous = -np.sin(cone) * np.cos(r - az)  # LOS of a unit wind from direction d
    k = np.arange(2, 5)[:, None, None, None]
    amp = 0.04 * rng.standard_normal((3, 1, 2, 5))
    phase = rng.uniform(0, 2 * np.pi, (3, 1, 2, 5))
    distortion = np.sum(amp * np.cos(k * r[None] + phase), axis=0)
    return lj.ResponseTable(d, homogeneous * (1.0 + 0.2 * np.cos(r)) + distortion)


@settings(max_examples=30, deadline=None)
@given(
    speed=st.floats(0.3, 40.0),
    direction=st.floats(0.0, 360.0, exclude_max=True),
    seed=st.integers(0, 5),
)
def test_exact_model_records_are_recovered_on_nonuniform_distorted_tables(speed, direction, seed):
    table = _distorted_table(seed)
    los = speed * table.response_at(jnp.asarray([direction]))
    inv = solve(table, los)
    assert np.all(inv.converged)
    assert np.all(inv.num_steps <= 8)
    # Gauss-Newton converges quadratically: once it steps, far below its tolerance (1e-6 of
    # the record's RMS LOS). A start (a tabulated direction) that already fits the record
    # within the tolerance is accepted on the first step: then the answer is as accurate as
    # the tolerance (a true direction within ~1e-4 degrees of a table direction).
    stepped = np.asarray(inv.num_steps) > 1
    err_u = np.abs(np.asarray(inv.speed) / speed - 1.0)
    err_d = np.abs(np.asarray(lj.wrap180(inv.direction - direction)))
    assert np.all(np.where(stepped, err_u < 1e-8, err_u < 1e-6)), (err_u, inv.num_steps)
    assert np.all(np.where(stepped, err_d < 1e-6, err_d < 1e-4)), (err_d, inv.num_steps)
    assert np.all(np.where(stepped, True, np.asarray(inv.residual_rms) < 1e-6 * speed))


def test_a_start_within_the_tolerance_is_accepted_as_accurately_as_the_tolerance():
    """A record 1e-5 degrees from a tabulated direction: the start fits it within the
    solver's tolerance and is accepted on the first step, within 1e-6 of the speed and 1e-4
    degrees (the case hypothesis found: speed 1 m/s, direction 1e-5)."""
    table = _distorted_table(0)
    inv = solve(table, 1.0 * table.response_at(jnp.asarray([1e-5])))
    assert np.all(inv.converged) and np.all(np.asarray(inv.num_steps) == 1)
    np.testing.assert_allclose(inv.speed, 1.0, rtol=1e-6)
    np.testing.assert_allclose(lj.wrap180(inv.direction - 1e-5), 0.0, atol=1e-4)


# -- per-backend batches and bucketed shapes (issue 18) ---------------------------------------
def _core_compilations(caplog):
    """How many times `invert`'s solver core has been compiled (JAX's compile log)."""
    return sum("Compiling jit(_invert_core)" in r.getMessage() for r in caplog.records)


@pytest.mark.parametrize("batch_size,lengths,most", [
    (32, (9, 12, 17, 20, 23), 2),  # 8 records per batch: 2, 2, 3, 3, 3 batches -> 2 shapes
    (None, (5, 6, 7, 8, 11), 3),  # one batch (512 problems on CPU): 6, 6, 8, 8, 12 records
])
def test_campaigns_of_different_lengths_compile_a_few_times(table, random_records, caplog,
                                                            batch_size, lengths, most):
    """Five files of different lengths: a handful of compilations (padded to buckets with
    dummy records), and each file's results are those of an unpadded solve."""
    import logging

    sims, _, _ = random_records
    los = np.asarray(sims.los)
    kw = dict(batch_size=batch_size, max_steps=29)  # a configuration no other test compiles
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        results = {n: lj.invert(table, los[:n], **kw) for n in lengths}
        compiled = _core_compilations(caplog)
        assert 1 <= compiled <= most, compiled
    # without buckets (inside jit the shapes are the caller's) the longest file's results are
    # the same ...
    n = lengths[-1]
    exact = jax.jit(lambda x: lj.invert(table, x, **kw))(jnp.asarray(los[:n]))
    for a, b in zip(jax.tree_util.tree_leaves(results[n]), jax.tree_util.tree_leaves(exact),
                    strict=True):
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-12, atol=1e-12)
    # ... and every length gives each record the same answer as the longest (so every file's
    # are the unpadded solve's: records are solved independently, tests above)
    longest = results[lengths[-1]]
    for n, inv in results.items():
        assert inv.speed.shape == (n, table.n_heights) and np.all(inv.converged)
        for a, b in zip(jax.tree_util.tree_leaves(inv), jax.tree_util.tree_leaves(longest),
                        strict=True):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b)[:n], rtol=1e-12, atol=1e-12)
    # leading axes of any shape share the same compilations
    m = lengths[-2]
    with jax.log_compiles(), caplog.at_level(logging.WARNING):
        twod = lj.invert(table, los[:m].reshape(2, m // 2, *los.shape[1:]), **kw)
        assert _core_compilations(caplog) == compiled  # the bucket of m records: compiled
    assert twod.speed.shape == (2, m // 2, table.n_heights)
    np.testing.assert_allclose(twod.speed.reshape(m, -1), longest.speed[:m], rtol=1e-12)


def test_batch_size_all_and_validation(table, random_records):
    sims, _, _ = random_records
    los = np.asarray(sims.los[:10])
    every = lj.invert(table, los, batch_size="all")
    small = lj.invert(table, los, batch_size=8)  # 2 records per batch, 5 batches (padded to 6)
    auto = lj.invert(table, los)
    for a, b, c in zip(jax.tree_util.tree_leaves(every), jax.tree_util.tree_leaves(small),
                       jax.tree_util.tree_leaves(auto), strict=True):
        np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(np.asarray(c), np.asarray(a), rtol=1e-12, atol=1e-12)
    for bad in (0, -5, 2.5, "everything"):
        with pytest.raises(ValueError, match="`batch_size` must be a positive int"):
            lj.invert(table, los, batch_size=bad)
        with pytest.raises(ValueError, match="invert_reconstructed: `batch_size`"):
            lj.invert_reconstructed(table, np.ones(4), np.ones(4), batch_size=bad)


def test_negative_reported_speed_is_impossible_not_the_opposite_direction(table):
    h = len(sites.HEIGHTS)
    speed = np.array([[9.0] * h, [-9.0] * h])
    direction = np.full((2, h), 200.0)
    inv = reconstructed(table, speed, direction)  # the program test_invert_reconstructed compiled
    assert np.all(np.isfinite(np.asarray(inv.speed[0])))
    assert np.all(np.isnan(np.asarray(inv.speed[1]))) and np.all(np.isnan(np.asarray(inv.direction[1])))
    flags = np.asarray(inv.flags[1])
    assert np.all(flags & lj.InverseFlag.IMPOSSIBLE_INPUT) and not np.any(inv.converged[1])
    assert not np.any(np.asarray(inv.flags[0]) & lj.InverseFlag.IMPOSSIBLE_INPUT)
