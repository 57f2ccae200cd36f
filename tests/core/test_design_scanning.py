"""Scan design: dual-Doppler positions (closed-form 90-degree crossing, a region against a grid
search of both positions) and the VAD's elevation and ray count (closed forms)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from lidarjax.design import (
    RegionBox,
    RegionRing,
    design_dual_doppler,
    design_vad,
    dual_doppler_variance,
    vad_variance,
)


def test_dual_doppler_variance_closed_form():
    """Level beams crossing at beta: var(u) + var(v) = 2 sigma^2 / sin^2(beta) (the inverse of
    the 2x2 matrix of unit rows), NaN for parallel beams."""
    for beta in (30.0, 60.0, 90.0, 135.0):
        b = np.deg2rad(beta)
        a = [1000.0, 0.0, 0.0]
        bb = [800.0 * np.cos(b), 800.0 * np.sin(b), 0.0]
        got = float(dual_doppler_variance(a, bb, [[0.0, 0.0, 0.0]], sigma=0.5)[0])
        assert got == pytest.approx(2 * 0.25 / np.sin(b) ** 2, rel=1e-12)
    assert np.isnan(dual_doppler_variance([1000.0, 0, 0], [500.0, 0, 0], [[0.0, 0, 0]])[0])


def test_dual_doppler_design_recovers_the_90_degree_crossing():
    """One target, lidars at 1000 m and 1500 m from it (bearings free): the optimum crossing is
    90 degrees (closed form above), found from a coarse stage that holds no such pair."""
    res = design_dual_doppler([[0.0, 0.0, 0.0]], RegionRing((0.0, 0.0), 1000.0),
                              RegionRing((0.0, 0.0), 1500.0), n_coarse=9, n_starts=3)
    assert res.feasible and res.converged
    assert abs(res.crossing_angle[0] - 90.0) < 0.5
    assert res.value == pytest.approx(2.0, rel=1e-6)
    np.testing.assert_allclose(np.linalg.norm(res.location_a[:2]), 1000.0)
    # the coarse grid's best pair crossed at 60 or 120 degrees: the local stage moved
    assert res.start_value > 2.5
    assert np.all(np.abs(res.gradient) < 1e-6)


def test_dual_doppler_region_beats_a_grid_search_of_both_positions():
    """Nine target points over 400 m x 400 m at 100 m; each lidar in a 1 km box at ground level:
    the design's mean variance is at most the best of a 12 x 12 x 12 x 12 grid search."""
    xs = np.linspace(-200.0, 200.0, 3)
    pts = np.array([(x, y, 100.0) for x in xs for y in xs])
    ra = RegionBox((-1500.0, -1000.0, 0.0), (-500.0, 1000.0, 0.0))
    rb = RegionBox((-1000.0, 500.0, 0.0), (1000.0, 1500.0, 0.0))
    res = design_dual_doppler(pts, ra, rb, n_coarse=81)
    assert res.feasible
    a = np.stack(np.meshgrid(np.linspace(-1500, -500, 12), np.linspace(-1000, 1000, 12),
                             indexing="ij"), -1).reshape(-1, 2)
    b = np.stack(np.meshgrid(np.linspace(-1000, 1000, 12), np.linspace(500, 1500, 12),
                             indexing="ij"), -1).reshape(-1, 2)

    @jax.jit
    def mean_var(pa, pb):
        la = jnp.concatenate([pa, jnp.zeros(1)])
        lb = jnp.concatenate([pb, jnp.zeros(1)])
        return jnp.mean(dual_doppler_variance(la, lb, pts))

    grid = jax.vmap(lambda pa: jax.vmap(lambda pb: mean_var(pa, pb))(jnp.asarray(b)))(
        jnp.asarray(a))
    best = float(jnp.nanmin(grid))
    assert res.value <= best * (1 + 1e-9)
    assert res.n_evaluations < a.shape[0] * b.shape[0] / 10
    # the gradient reported matches central differences of the same objective
    h = 1e-3
    x0 = res.x
    fd = []
    for e in np.eye(4):
        xp, xm = x0 + h * e, x0 - h * e
        fd.append((float(mean_var(jnp.asarray(xp[:2]), jnp.asarray(xp[2:])))
                   - float(mean_var(jnp.asarray(xm[:2]), jnp.asarray(xm[2:])))) / (2 * h))
    np.testing.assert_allclose(res.gradient, fd, rtol=1e-4, atol=1e-9)


def test_vad_variance_closed_form_and_design():
    """n evenly spaced rays at elevation e, equal noise: var(u) + var(v) = 4 sigma^2 /
    (n cos^2 e). With noise growing as range^k (range = h / sin e) the optimum elevation is
    atan(sqrt(k)), and the most rays win when every ray has the same noise; with a fixed scan
    time and a move time per ray, the fewest rays win (less time lost moving)."""
    for n, e in ((4, 20.0), (8, 45.0), (24, 70.0)):
        got = np.asarray(vad_variance(e, n, [50.0, 100.0], sigma=0.2))
        np.testing.assert_allclose(got, 4 * 0.04 / (n * np.cos(np.deg2rad(e)) ** 2), rtol=1e-10)
    res = design_vad([50.0, 100.0], n_rays=[4, 8, 16], range_exponent=2.0, n_coarse=8)
    assert res.feasible and res.n_rays == 16
    assert abs(res.elevation - np.rad2deg(np.arctan(np.sqrt(2.0)))) < 0.01
    assert abs(res.gradient) < 1e-8
    res = design_vad([50.0, 100.0], n_rays=[4, 8, 16], range_exponent=1.0, scan_time=20.0,
                     move_time=1.0, n_coarse=8)
    assert res.n_rays == 4 and abs(res.elevation - 45.0) < 0.01
    # optima on the elevation's bounds (the same compiled search): with equal noise the
    # lowest elevation wins (4 sigma^2 / (n cos^2 e) grows with e); with noise growing as
    # range^2 an upper bound below atan(sqrt(2)) = 54.7 degrees wins; both converge there
    for kw, bound in ((dict(range_exponent=0.0), 5.0),
                      (dict(range_exponent=2.0, elevation=(5.0, 40.0)), 40.0)):
        res = design_vad([50.0, 100.0], n_rays=[4, 8, 16], n_coarse=8, **kw)
        assert res.converged and res.message == "converged"
        assert res.elevation == bound and res.n_rays == 16
        e = np.deg2rad(bound)
        k = kw["range_exponent"]
        want = np.mean([4 * 0.01 * (h / (100.0 * np.sin(e))) ** (2 * k) / (16 * np.cos(e) ** 2)
                        for h in (50.0, 100.0)])
        assert res.value == pytest.approx(want, rel=1e-12)
        assert res.gradient * (1.0 if bound == 5.0 else -1.0) > 0  # pointing out of the box
    # (the heights and ray counts of the call above: its compiled search serves this one)
    res = design_vad([50.0, 100.0], n_rays=[4, 8, 16], scan_time=6.0, move_time=1.0,
                     n_coarse=8)
    # 8 and 16 rays leave no accumulation time (6 s / n - 1 s <= 0)
    assert res.n_rays == 4 and np.isnan(res.values[1:]).all() and np.isfinite(res.values[0])
    with pytest.raises(ValueError, match="n_rays"):
        design_vad([50.0], n_rays=[2])
    with pytest.raises(ValueError, match="points"):
        design_dual_doppler(np.zeros((0, 3)), RegionRing((0, 0), 1.0), RegionRing((0, 0), 2.0))
