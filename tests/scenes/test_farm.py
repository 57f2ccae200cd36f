"""Wind-farm scene: overlap area (closed cases, Monte Carlo, derivatives at the case
boundaries), FLORIS agreement (Jensen + Jimenez, every combination rule), the upstream-order
solve, gradients, float32 at UTM coordinates. (The scene inside simulate_rotations, response
tables and gradients through simulate: tests/cli/test_farm.py's CLI and nacelle tests.)"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.scenes import farm as fm

from ..helpers import central_difference

RNG = np.random.default_rng(14)


# ---------------------------------------------------------------------------- overlap area
def lens(r, d):
    """Overlap of two equal circles of radius r, d apart (textbook closed form)."""
    return 2 * r * r * np.arccos(d / (2 * r)) - 0.5 * d * np.sqrt(4 * r * r - d * d)


def test_overlap_closed_cases():
    a = lambda r1, r2, d: float(fm.overlap_area(r1, r2, d))  # noqa: E731
    assert a(60.0, 50.0, 110.0) == 0.0 and a(60.0, 50.0, 500.0) == 0.0       # eq. 2
    assert a(80.0, 50.0, 30.0) == pytest.approx(np.pi * 2500.0, rel=1e-15)  # eq. 6
    assert a(80.0, 50.0, 0.0) == pytest.approx(np.pi * 2500.0, rel=1e-15)   # concentric
    assert a(40.0, 50.0, 5.0) == pytest.approx(np.pi * 1600.0, rel=1e-15)   # wake inside disc
    for d in (1.0, 30.0, 50.0, 99.0):                                        # eq. 4, r1 = r2
        assert a(50.0, 50.0, d) == pytest.approx(lens(50.0, d), rel=1e-12)
    # continuity at both case boundaries
    for r1, r2 in ((80.0, 50.0), (50.0, 80.0), (63.0, 63.0 + 1e-9)):
        for edge in (r1 + r2, abs(r1 - r2)):
            lo, hi = a(r1, r2, edge - 1e-7), a(r1, r2, edge + 1e-7)
            assert abs(lo - hi) < 1e-4 * max(r1, r2), (r1, r2, edge, lo, hi)


def test_overlap_monte_carlo():
    n = 400_000
    for r1, r2, d in ((80.0, 50.0, 60.0), (50.0, 63.0, 40.0), (70.0, 63.0, 120.0)):
        # uniform points in the rotor disc: fraction inside the wake circle
        rho = r2 * np.sqrt(RNG.uniform(size=n))
        phi = RNG.uniform(0, 2 * np.pi, n)
        x, y = rho * np.cos(phi), rho * np.sin(phi)
        p = np.mean((x - d) ** 2 + y**2 < r1 * r1)
        est, sd = p * np.pi * r2**2, np.sqrt(p * (1 - p) / n) * np.pi * r2**2
        assert abs(float(fm.overlap_area(r1, r2, d)) - est) < 4.5 * sd + 1e-9, (r1, r2, d)


@pytest.mark.parametrize("r1,r2", [(80.0, 50.0), (50.0, 80.0), (63.0, 63.0)])
def test_overlap_derivatives_finite_and_exact(r1, r2):
    grad = jax.jit(jax.grad(lambda p: fm.overlap_area(p[0], p[1], p[2])))
    ds = [0.0, 1e-12, abs(r1 - r2), abs(r1 - r2) + 1e-9, 0.5 * (r1 + r2), r1 + r2 - 1e-9,
          r1 + r2, r1 + r2 + 1e-9, 1e3]
    for d in ds:
        g = np.asarray(grad(jnp.array([r1, r2, d])))
        assert np.all(np.isfinite(g)), (d, g)
    for d in (abs(r1 - r2) + 7.0, 0.5 * (r1 + r2) + 3.0, r1 + r2 - 5.0):
        x = np.array([r1, r2, d])
        g = np.asarray(grad(jnp.asarray(x)))
        fd = central_difference(lambda p: fm.overlap_area(p[0], p[1], p[2]), x, 1e-5)
        np.testing.assert_allclose(g, fd, rtol=1e-7, atol=1e-6)
    # forward mode agrees with reverse mode (custom_jvp)
    x = jnp.array([r1, r2, 0.5 * (r1 + r2)])
    np.testing.assert_allclose(jax.jacfwd(lambda p: fm.overlap_area(*p))(x), grad(x), rtol=1e-12)


# ---------------------------------------------------------------------------------- FLORIS
@pytest.fixture(autouse=True, scope="module")
def _floris_path_lookup_without_source_context():
    """FLORIS resolves each turbine's library path (`floris.type_dec.convert_to_path`, run for
    every turbine each time a model is built, set or run) by reading the file names of
    ``inspect.stack()``, which also loads every frame's source lines and, for frames without a
    file (attrs-generated methods), scans all of ``sys.modules`` (thousands with JAX loaded):
    about 2/3 of these tests' CPU. The same file names, read from the frames directly (what
    ``stack()[k].filename`` gives for frames of existing files; the paths resolve the same)."""
    import sys
    import types

    try:
        from floris import type_dec
    except ImportError:  # the FLORIS tests then fail on their own import
        yield
        return
    real = type_dec.inspect

    def stack():
        frame, frames = sys._getframe(1), []
        while frame is not None:
            frames.append(types.SimpleNamespace(filename=frame.f_code.co_filename))
            frame = frame.f_back
        return frames

    type_dec.inspect = types.SimpleNamespace(stack=stack)
    yield
    type_dec.inspect = real


LAYOUT_X = [0.0, 630.0, 1260.0, 300.0]
LAYOUT_Y = [0.0, 20.0, -40.0, 300.0]
YAW = [20.0, -10.0, 0.0, 5.0]


def _points(n=600):
    return np.stack([RNG.uniform(-200, 2500, n), RNG.uniform(-400, 600, n),
                     RNG.uniform(5, 180, n)], -1)


@pytest.mark.parametrize("combination", fm.COMBINATIONS)
def test_points_match_floris(combination):
    import floris  # noqa: F401  (the test extra brings it)
    pts = _points()
    for direction in ((270.0, 253.0) if combination == "sum_of_squares" else (253.0,)):
        farm = lj.scenes.wind_farm(LAYOUT_X, LAYOUT_Y, 90.0, 126.0, ct=0.8, yaw=YAW, speed=8.0,
                                   direction=direction, combination=combination, ad=-4.5, bd=-0.01)
        model = fm.to_floris(farm)
        u_floris = model.sample_flow_at_points(*pts.T)[0]
        u = np.asarray(farm.streamwise_local(jnp.asarray(pts)))
        waked = u_floris < 8.0 - 1e-9
        assert waked.mean() > 0.2  # the points do sample the wakes
        # away from wake edges: the cone boundary r = R + k dx, the disc plane, yaw deflection
        np.testing.assert_allclose(u, u_floris, rtol=0, atol=1e-4)


def test_inflow_matches_floris_where_same():
    """Full or no overlap: FLORIS's 3x3 rotor grid and the overlap average agree exactly;
    partial overlap: they differ (documented: the grid sees a +-R/2 square only)."""
    import floris  # noqa: F401  (the test extra brings it)
    x = [0.0, 504.0, 1008.0, 0.0]
    y = [0.0, 0.0, 0.0, 600.0]
    for comb in fm.COMBINATIONS:
        farm = lj.scenes.wind_farm(x, y, 90.0, 126.0, ct=0.75, speed=9.0, combination=comb)
        model = fm.to_floris(farm)
        model.run()
        np.testing.assert_allclose(np.asarray(farm.solve().inflow),
                                   model.turbine_average_velocities[0], rtol=0, atol=1e-4)
    # partial overlap (lateral offset 70 m, R = 63 m): FLORIS reads a 3x3 grid over the
    # central +-R/2 square (cubic mean), lidarjax the exact disc average of the same wake
    farm = lj.scenes.wind_farm([0.0, 504.0], [0.0, 70.0], 90.0, 126.0, ct=0.75, speed=9.0)
    model = fm.to_floris(farm)
    model.run()
    ours, theirs = np.asarray(farm.solve().inflow)[1], model.turbine_average_velocities[0, 1]
    assert abs(ours - theirs) < 0.05
    # the overlap average is the disc average of the point field (fine polar quadrature)
    r = 63.0 * np.sqrt((np.arange(400) + 0.5) / 400)
    t = (np.arange(720) + 0.5) * 2 * np.pi / 720
    disc = np.stack(np.broadcast_arrays(504.0, 70.0 + np.outer(r, np.cos(t)),
                                        90.0 + np.outer(r, np.sin(t))), -1)
    brute = np.asarray(farm.streamwise_local(jnp.asarray(disc))).mean()
    assert ours == pytest.approx(brute, abs=2e-3)


def test_floris_nrel_5mw_curve_as_shipped():
    """FLORIS's own NREL 5 MW turbine (Ct up to 1.13 below cut-in, clipped as FLORIS clips it):
    accepted, and within the documented difference from FLORIS: FLORIS reads the curve at
    its 3x3 rotor grid's cubic-mean speed, lidarjax at the exact disc average."""
    from pathlib import Path

    import floris
    import yaml  # noqa: F401  (the test extra brings it)

    from lidarjax.io import read_turbine_type

    path = Path(floris.__file__).parent / "turbine_library" / "nrel_5MW.yaml"
    with pytest.warns(UserWarning, match="clipped"):
        t = read_turbine_type(path)
    farm = lj.scenes.wind_farm(LAYOUT_X, LAYOUT_Y, t.hub_height, t.diameter,
                               ct=(t.speed, t.ct), speed=8.0, direction=262.0)
    model = fm.to_floris(farm)
    pts = _points()
    u_floris = model.sample_flow_at_points(*pts.T)[0]
    u = np.asarray(farm.streamwise_local(jnp.asarray(pts)))
    assert (u_floris < 8.0 - 1e-9).mean() > 0.2
    err = np.abs(u - u_floris)  # measured: max 0.065 m/s, 99th percentile 0.044 m/s
    assert err.max() < 0.08 and np.percentile(err, 99) < 0.05
    model.run()
    inflow = np.abs(np.asarray(farm.solve().inflow) - model.turbine_average_velocities[0])
    assert inflow.max() < 0.25  # measured 0.17 m/s (partial overlap: rotor grid vs disc)


# ----------------------------------------------------------------------- turbine interaction
def test_upstream_order_and_thrust_curve():
    speeds = np.array([3.0, 5.0, 7.0, 9.0, 11.0, 13.0])
    cts = np.array([0.0, 0.85, 0.8, 0.75, 0.55, 0.3])
    e, n = np.array([0.0, 500.0, 1000.0, 1500.0]), np.zeros(4)
    farm = lj.scenes.wind_farm(e, n, 90.0, 120.0, ct=(speeds, cts), speed=12.0)
    st = farm.solve()
    u = np.asarray(st.inflow)
    assert u[0] == pytest.approx(12.0) and np.all(np.diff(u) < 0)
    np.testing.assert_allclose(np.asarray(st.ct), np.interp(u, speeds, cts), rtol=1e-12)
    # input order does not matter (argsort inside), nor does the wind turning 180 degrees
    perm = [2, 0, 3, 1]
    farm_p = lj.scenes.wind_farm(e[perm], n[perm], 90.0, 120.0, ct=(speeds, cts), speed=12.0,
                                 origin=(0.0, 0.0))
    np.testing.assert_allclose(np.asarray(farm_p.solve().inflow), u[perm], rtol=1e-12)
    back = lj.scenes.wind_farm(e, n, 90.0, 120.0, ct=(speeds, cts), speed=12.0, direction=90.0)
    np.testing.assert_allclose(np.asarray(back.solve().inflow), u[::-1], rtol=1e-12)
    # a hand calculation for turbine 1 (fully waked by turbine 0, one wake)
    ct0 = np.interp(12.0, speeds, cts)
    a0 = (1 - np.sqrt(1 - ct0)) / 2
    c = (60.0 / (60.0 + 0.05 * 500.0 + fm.EPS)) ** 2
    assert u[1] == pytest.approx(12.0 * (1 - 2 * a0 * c), rel=1e-12)


def test_reference_points_and_heading():
    farm = lj.scenes.wind_farm([0.0, 400.0], [0.0, 0.0], 80.0, 100.0, direction=0.0)
    ref = np.asarray(farm.reference_points())
    np.testing.assert_allclose(ref, [[0.0, 100.0, 80.0], [400.0, 100.0, 80.0]], atol=1e-12)


# --------------------------------------------------------------------------------- gradients
GAUSS = lj.scenes.wind_farm([0.0, 560.0, 1100.0], [0.0, 0.0, -30.0], 90.0, 126.0,
                            ct=(np.array([4.0, 8.0, 12.0]), np.array([0.85, 0.78, 0.5])),
                            yaw=[15.0, -5.0, 0.0], speed=9.0, direction=265.0, alpha=0.12,
                            model="gaussian", ad=-4.5, bd=-0.01)
# in the far wake, at the disc planes, just behind and just ahead of a disc, on a centre line
PROBE_PTS = jnp.array([[1500.0, 10.0, 95.0], [800.0, -60.0, 60.0], [1200.0, 30.0, 120.0],
                       [0.0, 0.0, 90.0], [560.0 + 1e-9, 0.0, 90.0], [555.0, 0.0, 90.0],
                       [30.0, 0.0, 90.0]])


NAMES = ("x", "y", "yaw", "ct_value", "speed", "direction")


def _loss(farm, pts):
    def loss(params):
        import equinox as eqx
        f = eqx.tree_at(lambda g: tuple(getattr(g, n) for n in NAMES), farm, tuple(params))
        return jnp.sum(f.streamwise_local(pts) ** 2) + jnp.sum(f.solve().inflow)
    return jax.jit(loss)


def _check_grads(farm, steps, rtol, pts=PROBE_PTS):
    loss = _loss(farm, pts)
    p0 = [jnp.asarray(getattr(farm, n)) for n in NAMES]
    grads = jax.grad(loss)(p0)
    for k, (name, eps) in enumerate(zip(NAMES, steps, strict=True)):
        g = np.asarray(grads[k])
        assert np.all(np.isfinite(g)), name

        def one(v, k=k):
            return loss([v if j == k else p0[j] for j in range(len(p0))])
        fd = central_difference(one, np.asarray(p0[k]), eps)
        np.testing.assert_allclose(g, fd, rtol=rtol, atol=1e-6 * max(np.abs(fd).max(), 1e-3),
                                   err_msg=name)


def test_gaussian_gradients_match_fd():
    """Finite everywhere (disc planes, aligned turbines, upstream) and equal to centred
    differences, for positions, yaw, thrust curve, speed and direction."""
    _check_grads(GAUSS, (1e-3, 1e-3, 1e-4, 1e-6, 1e-6, 1e-5), 2e-5)


def test_top_hat_gradients_away_from_edges():
    farm = lj.scenes.wind_farm([0.0, 560.0, 1100.0], [0.0, 40.0, -30.0], 90.0, 126.0,
                               ct=(np.array([4.0, 8.0, 12.0]), np.array([0.85, 0.78, 0.5])),
                               yaw=[15.0, -5.0, 0.0], speed=9.0, direction=265.0)
    _check_grads(farm, (1e-3, 1e-3, 1e-4, 1e-6, 1e-6, 1e-6), 1e-5, PROBE_PTS[:3])


# ------------------------------------------------------------------- precision and batching
def test_float32_at_utm():
    e = 451_234.5 + np.array([0.0, 630.0, 1260.0])
    n = 6_123_456.25 + np.array([0.0, 20.0, -40.0])
    pts = np.stack([e[0] + np.linspace(100, 1800, 40), np.full(40, n[0] + 10.0),
                    np.full(40, 95.0)], -1)
    kw = dict(ct=0.8, speed=8.0, direction=268.0, model="gaussian")
    f64 = lj.scenes.wind_farm(e, n, 90.0, 126.0, **kw)
    f32 = lj.scenes.wind_farm(e, n, 90.0, 126.0, dtype=jnp.float32, **kw)
    u64, u32 = np.asarray(f64.sample(pts)), np.asarray(f32.sample(pts))  # compiled once each
    assert u32.dtype == np.float32
    np.testing.assert_allclose(u32, u64, atol=2e-5 * 8.0)


def test_bad_inputs():
    with pytest.raises(ValueError, match="share one position"):
        lj.scenes.wind_farm([0.0, 0.0], [5.0, 5.0], 90.0, 126.0)
    with pytest.raises(ValueError, match="unknown model"):
        lj.scenes.wind_farm([0.0], [0.0], 90.0, 126.0, model="curl")
    with pytest.raises(ValueError, match="strictly increasing"):
        lj.scenes.wind_farm([0.0], [0.0], 90.0, 126.0, ct=([5.0, 4.0], [0.8, 0.7]))
    with pytest.raises(ValueError, match="below its rotor"):
        lj.scenes.wind_farm([0.0], [0.0], 50.0, 126.0)
