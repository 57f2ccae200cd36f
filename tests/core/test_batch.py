"""Skipping what a scene does not need: trace-time branches, cropping, batching."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.forward import _simulate

X = np.linspace(-300.0, 300.0, 31)
Y = np.linspace(-250.0, 350.0, 25)
Z = np.linspace(0.0, 240.0, 25)
HILL = lj.scenes.hill(height=30.0, half_width=150.0, speed=9.0, direction=250.0)
FIELD = lj.GridField.from_function(HILL.sample, X, Y, Z)
MOUNT = lj.Mount([12.0, -7.0, 31.0], beta=25.0, gamma=3.0, psi=180.0)
HEIGHTS = np.array([30.0, 60.0, 100.0])
PROBES = {"point": lj.PointProbe(), "pulsed": lj.PulsedProbe(), "cw": lj.CWProbe(n_nodes=9)}


def primitives(jaxpr) -> list[str]:
    """Every primitive name in a jaxpr, nested jaxprs (jit, vmap, cond) included."""
    out = []
    for eqn in jaxpr.eqns:
        out.append(eqn.primitive.name)
        for v in eqn.params.values():
            for sub in v if isinstance(v, list | tuple) else [v]:
                inner = getattr(sub, "jaxpr", sub)
                if hasattr(inner, "eqns"):
                    out += primitives(inner)
    return out


def graph(scan, probe, *, u_ref=None, point_reference=False):
    fn = functools.partial(_simulate, point_reference=point_reference)
    u = None if u_ref is None else jnp.asarray(u_ref)
    return jax.make_jaxpr(fn)(FIELD, scan, MOUNT, jnp.asarray(HEIGHTS), u, probe, 1e-4).jaxpr


def gathers(jaxpr) -> list[tuple]:
    return [e.outvars[0].aval.shape for e in jaxpr.eqns if e.primitive.name == "gather"]


def test_branches_are_resolved_at_trace_time():
    v1, v2 = lj.windcube_v1(), lj.windcube_v2()
    base = graph(v1, PROBES["point"])
    prims = primitives(base)
    # the point probe compiles one trilinear lookup: four 6-number gathers, no quadrature
    assert prims.count("gather") == 4 and "erf" not in prims and "tan" not in prims
    assert all(shape == (3, 4, 6) for shape in gathers(base))  # V1: 4 beams, no vertical
    assert all(shape == (3, 5, 6) for shape in gathers(graph(v2, PROBES["point"])))
    # the point reference adds exactly one more lookup, only when asked
    with_point = primitives(graph(v1, PROBES["point"], point_reference=True))
    assert with_point.count("gather") == 8
    # correction factors only with u_ref
    no_ref, with_ref = base, graph(v1, PROBES["point"], u_ref=[1.0, 0.0, 0.0])
    assert len(primitives(with_ref)) > len(primitives(no_ref)) + 20
    assert primitives(no_ref).count("atan2") == 0 and primitives(with_ref).count("atan2") >= 1
    # probes: the pulsed weighting (erf) and the CW nodes appear only with them
    pulsed = graph(v1, PROBES["pulsed"])
    assert "erf" in primitives(pulsed)
    assert all(shape == (3, 4, 9, 6) for shape in gathers(pulsed))
    assert "erf" not in primitives(graph(v1, PROBES["cw"]))
    sim = lj.simulate(FIELD, v1, MOUNT, HEIGHTS, point_reference=False)
    assert sim.point_velocity is None and sim.cff_U is None and sim.cfp_U is None


@pytest.mark.parametrize("probe", list(PROBES))
def test_crop_to_scan_bounds_is_bit_exact(probe):
    probe = PROBES[probe]
    scan = lj.windcube_v2()
    lo, hi = lj.scan_bounds(scan, MOUNT, HEIGHTS, probe)
    small = FIELD.crop(lo, hi)
    assert small.nbytes < FIELD.nbytes / 2
    full = lj.simulate(FIELD, scan, MOUNT, HEIGHTS, probe=probe, u_ref=[9.0, 3.0, 0.0])
    cut = lj.simulate(small, scan, MOUNT, HEIGHTS, probe=probe, u_ref=[9.0, 3.0, 0.0])
    for a, b in zip(jax.tree_util.tree_leaves(full), jax.tree_util.tree_leaves(cut), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert np.all(np.isfinite(full.los))
    # the box holds every focus point and the column above the lidar
    pts = np.asarray(full.points).reshape(-1, 3)
    assert np.all(pts >= lo - 1e-9) and np.all(pts <= hi + 1e-9)


def test_crop_edges_and_errors():
    # a box past the grid's corner is clipped to the grid, margin included
    corner = FIELD.crop([250.0, 300.0, 200.0], [400.0, 400.0, 300.0])
    assert corner.shape == (5, 4, 6)  # nodes bracketing the box plus one on each side
    assert float(corner.x[-1]) == 300.0 and float(corner.x[0]) == 220.0
    p = jnp.array([[290.0, 349.0, 239.0], [241.0, 331.0, 221.0]])
    np.testing.assert_array_equal(corner.sample(p), FIELD.sample(p))
    assert np.isnan(corner.sample(jnp.array([200.0, 340.0, 230.0]))).all()  # outside the crop
    with pytest.raises(ValueError, match="misses"):
        FIELD.crop([400.0, 0.0, 0.0], [500.0, 1.0, 1.0])
    with pytest.raises(ValueError, match="lo <= hi"):
        FIELD.crop([1.0, 0.0, 0.0], [0.0, 1.0, 1.0])


def test_crop_keeps_stretched_axes_exact():
    z = np.array([0.0, 5.0, 12.0, 22.0, 40.0, 70.0, 110.0, 160.0, 240.0])
    field = lj.GridField.from_function(HILL.sample, X, Y, z)
    assert field.uniform == (True, True, False)
    lo, hi = lj.scan_bounds(lj.windcube_v1(), MOUNT, HEIGHTS)
    a = lj.simulate(field, lj.windcube_v1(), MOUNT, HEIGHTS)
    b = lj.simulate(field.crop(lo, hi), lj.windcube_v1(), MOUNT, HEIGHTS)
    np.testing.assert_array_equal(a.los, b.los)
    np.testing.assert_array_equal(a.point_velocity, b.point_velocity)


DIRECTIONS = (230.0, 250.0, 270.0)
SECTOR_FIELDS = [
    lj.GridField.from_function(
        lj.scenes.hill(height=30.0, half_width=150.0, speed=9.0, direction=d).sample, X, Y, Z)
    for d in DIRECTIONS
]
SECTOR_MOUNTS = [lj.Mount([12.0, -7.0, 31.0], beta=b, psi=180.0) for b in (0.0, 20.0, 40.0)]
U_REFS = jnp.stack([9.0 * lj.heading(d) for d in DIRECTIONS])


def test_simulate_sectors_matches_a_loop():
    probe = PROBES["pulsed"]
    scan = lj.windcube_v2()
    sims = lj.simulate_rotations(SECTOR_FIELDS, scan, SECTOR_MOUNTS, HEIGHTS, u_refs=U_REFS,
                               probe=probe)
    assert sims.los.shape == (3, 3, 5) and sims.cff_U.shape == (3, 3)
    for k in range(3):
        one = lj.simulate(SECTOR_FIELDS[k], scan, SECTOR_MOUNTS[k], HEIGHTS, u_ref=U_REFS[k],
                          probe=probe)
        for a, b in zip(jax.tree_util.tree_leaves(one), jax.tree_util.tree_leaves(sims),
                        strict=True):
            np.testing.assert_allclose(np.asarray(b)[k], a, rtol=1e-13, atol=1e-13)
    # a shared mount and u_ref, and a pre-stacked field, broadcast over the sectors
    stacked = lj.stack_fields(SECTOR_FIELDS)
    shared = lj.simulate_rotations(stacked, scan, MOUNT, HEIGHTS, u_refs=U_REFS[0], probe=probe)
    one = lj.simulate(SECTOR_FIELDS[2], scan, MOUNT, HEIGHTS, u_ref=U_REFS[0], probe=probe)
    np.testing.assert_allclose(shared.lidar_velocity[2], one.lidar_velocity, rtol=1e-13)
    # one field seen from several mounts
    mounts = lj.simulate_rotations(FIELD, scan, SECTOR_MOUNTS, HEIGHTS, probe=probe)
    one = lj.simulate(FIELD, scan, SECTOR_MOUNTS[1], HEIGHTS, probe=probe)
    np.testing.assert_allclose(mounts.los[1], one.los, rtol=1e-13)


def test_stack_fields_needs_one_grid():
    other = lj.GridField.from_function(HILL.sample, X + 1.0, Y, Z)
    with pytest.raises(ValueError, match="share their grid"):
        lj.stack_fields([FIELD, other])
    with pytest.raises(ValueError, match="one type"):
        lj.stack_fields([FIELD, HILL])
    with pytest.raises(ValueError, match="2 mounts for 3 sectors"):
        lj.simulate_rotations(SECTOR_FIELDS, lj.windcube_v1(), SECTOR_MOUNTS[:2], HEIGHTS)
    with pytest.raises(ValueError, match="nothing to batch"):
        lj.simulate_rotations(FIELD, lj.windcube_v1(), MOUNT, HEIGHTS)
    scenes = lj.stack_fields([lj.scenes.hill(direction=d) for d in DIRECTIONS])
    assert scenes.direction.shape == (3,)
    assert float(lj.unstack_field(scenes, 1).direction) == 250.0


def test_vmap_over_mounts_cones_heights_and_probe_parameters_matches_a_loop():
    mounts = lj.stack_mounts(SECTOR_MOUNTS)
    cones = jnp.array([20.0, 28.0, 35.0])
    heights = jnp.stack([HEIGHTS, HEIGHTS + 5.0, HEIGHTS * 1.5])
    fwhm = jnp.array([15.0, 26.0, 40.0])

    def run(mount, cone, h, w):
        scan = lj.Scan(jnp.array([0.0, 90.0, 180.0, 270.0]), cone, method="windcube_v1")
        probe = lj.PulsedProbe(w, 25.0, n_nodes=5)
        return lj.simulate(FIELD, scan, mount, h, probe=probe).lidar_velocity

    batched = jax.vmap(run)(mounts, cones, heights, fwhm)
    for k in range(3):
        single = run(SECTOR_MOUNTS[k], float(cones[k]), heights[k], float(fwhm[k]))
        np.testing.assert_allclose(batched[k], single, rtol=1e-13, atol=1e-13)


def test_scan_bounds_union_over_mounts():
    scan = lj.windcube_v1()
    boxes = [lj.scan_bounds(scan, m, HEIGHTS) for m in SECTOR_MOUNTS]
    lo, hi = lj.scan_bounds(scan, lj.stack_mounts(SECTOR_MOUNTS), HEIGHTS)
    np.testing.assert_array_equal(lo, np.min([b[0] for b in boxes], axis=0))
    np.testing.assert_array_equal(hi, np.max([b[1] for b in boxes], axis=0))
    lo_p, hi_p = lj.scan_bounds(scan, SECTOR_MOUNTS, HEIGHTS, lj.PulsedProbe())
    assert np.all(lo_p <= lo) and np.all(hi_p >= hi)
    # no point reference: the column above the lidar is only needed up to the beams
    lo_n, hi_n = lj.scan_bounds(scan, MOUNT, HEIGHTS, point_reference=False)
    assert hi_n[2] == pytest.approx(31.0 + HEIGHTS[-1])


# -- batched mounts (issue 18): built from arrays, stacked linearly ----------------------------
ROT_BETAS = np.array([0.0, 35.0, 110.0, 250.0])
ROT_PITCH = np.array([0.0, 2.0, -3.0, 1.5])


def test_simulate_rotations_with_a_batched_mount_equals_per_mount_simulate():
    scan, probe = lj.windcube_v2(), PROBES["pulsed"]
    mount = lj.Mount([12.0, -7.0, 31.0], beta=ROT_BETAS, psi=180.0, pitch=ROT_PITCH)
    sims = lj.simulate_rotations(FIELD, scan, mount, HEIGHTS, u_refs=U_REFS[0], probe=probe)
    assert sims.los.shape == (4, 3, 5)
    for k in range(4):
        one = lj.simulate(FIELD, scan, lj.Mount([12.0, -7.0, 31.0], beta=ROT_BETAS[k], psi=180.0,
                                                pitch=ROT_PITCH[k]),
                          HEIGHTS, u_ref=U_REFS[0], probe=probe)
        for a, b in zip(jax.tree_util.tree_leaves(one), jax.tree_util.tree_leaves(sims),
                        strict=True):
            np.testing.assert_allclose(np.asarray(b)[k], a, rtol=1e-13, atol=1e-13)
    # the same batch as a list of single mounts, and one per field of a stack
    listed = lj.simulate_rotations(FIELD, scan, list(mount), HEIGHTS, u_refs=U_REFS[0],
                                   probe=probe)
    np.testing.assert_array_equal(listed.los, sims.los)
    per_field = lj.simulate_rotations(SECTOR_FIELDS, scan, mount[:3], HEIGHTS, u_refs=U_REFS)
    one = lj.simulate(SECTOR_FIELDS[1], scan, mount[1], HEIGHTS, u_ref=U_REFS[1])
    np.testing.assert_allclose(per_field.cff_U[1], one.cff_U, rtol=1e-13)
    with pytest.raises(ValueError, match="4 mounts for 3 sectors|'mounts': 4"):
        lj.simulate_rotations(SECTOR_FIELDS, scan, mount, HEIGHTS)
    with pytest.raises(ValueError, match="list of Mounts"):
        lj.simulate_rotations(FIELD, scan, [mount[0], "mount"], HEIGHTS)


def test_gradients_through_a_batched_mount_equal_the_single_mount_ones():
    scan = lj.windcube_v2()

    def total(betas, pitches):
        m = lj.Mount([12.0, -7.0, 31.0], beta=betas, psi=180.0, pitch=pitches)
        return jnp.sum(lj.simulate_rotations(HILL, scan, m, HEIGHTS).lidar_speed)

    def single(beta, pitch):
        m = lj.Mount([12.0, -7.0, 31.0], beta=beta, psi=180.0, pitch=pitch)
        return jnp.sum(lj.simulate(HILL, scan, m, HEIGHTS).lidar_speed)

    # each gradient one compiled function (eagerly, the inner jit compiles a forward pass and
    # its transpose)
    g_beta, g_pitch = jax.jit(jax.grad(total, argnums=(0, 1)))(jnp.asarray(ROT_BETAS),
                                                               jnp.asarray(ROT_PITCH))
    assert np.all(np.isfinite(g_beta)) and np.all(np.isfinite(g_pitch))
    assert np.all(g_beta != 0) and np.all(g_pitch != 0)
    grad_one = jax.jit(jax.grad(single, argnums=(0, 1)))
    for k in range(4):
        gb, gp = grad_one(jnp.asarray(ROT_BETAS[k]), jnp.asarray(ROT_PITCH[k]))
        np.testing.assert_allclose(g_beta[k], gb, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(g_pitch[k], gp, rtol=1e-12, atol=1e-15)


def test_stack_mounts_concatenates_batches_keeps_dtypes_and_checks_items():
    a = lj.Mount(np.arange(6.0).reshape(2, 3), beta=[1.0, 2.0])
    b = lj.Mount([7.0, 8.0, 9.0], beta=3.0)
    c = lj.Mount(np.ones((3, 3)), beta=[4.0, 5.0, 6.0], roll=0.5)
    s = lj.stack_mounts([a, b, c])
    assert s.batch_shape == (6,)
    np.testing.assert_array_equal(s.beta, [1.0, 2.0, 3.0, 4.0, 5.0, 6.0])
    np.testing.assert_array_equal(s.roll, [0.0, 0.0, 0.0, 0.5, 0.5, 0.5])
    np.testing.assert_array_equal(s.location[2], [7.0, 8.0, 9.0])
    assert lj.stack_mounts(a) is a and lj.stack_mounts(b).batch_shape == (1,)
    # float32 with float64 promotes as jnp.stack would
    f32 = lj.Mount(np.array([1.0, 2.0, 3.0], np.float32), beta=np.float32(1.0))
    mixed = lj.stack_mounts([f32, b])
    assert mixed.location.dtype == mixed.beta.dtype == jnp.float64
    same = lj.stack_mounts([f32, f32])
    assert same.location.dtype == same.beta.dtype == jnp.float32
    # traced mounts stack too (inside jit)
    traced = jax.jit(lambda x: lj.stack_mounts([lj.Mount(x, beta=x[0]), b]).beta)(
        jnp.array([5.0, 0.0, 0.0]))
    np.testing.assert_array_equal(traced, [5.0, 3.0])
    with pytest.raises(ValueError, match="at least one mount"):
        lj.stack_mounts([])
    with pytest.raises(ValueError, match="item 1 is a str"):
        lj.stack_mounts([b, "b"])


def test_ten_thousand_rotations_build_in_well_under_seconds():
    """Issue 18: a batched Mount from arrays, and `stack_mounts` of 10,000 single mounts, in
    well under a few seconds (the old pairwise stack took 264 s for 10,000, quadratic in the
    count). Wall-clock bounds on a shared 2-core CI machine are noisy (a loaded run measured
    3.2 s where an idle one takes 0.3 s), so the test asserts what the fix is about: linear
    cost (10,000 mounts cost at most 25 times 1,000, best of two runs after the one-time
    compilation; quadratic would be 100 times) and a loose absolute bound."""
    import time

    n = 10_000
    betas = np.linspace(0.0, 360.0, n, endpoint=False)
    locs = np.tile([12.0, -7.0, 31.0], (n, 1)) + np.linspace(0.0, 1.0, n)[:, None]
    t = time.perf_counter()
    batched = lj.Mount(locs, beta=betas, psi=180.0)
    jax.block_until_ready(batched)
    t_arrays = time.perf_counter() - t
    singles = [lj.Mount(locs[k], beta=betas[k], psi=180.0) for k in range(n)]

    def best_of_two(mounts):
        times = []
        for _ in range(2):
            t = time.perf_counter()
            out = lj.stack_mounts(mounts)
            jax.block_until_ready(out)
            times.append(time.perf_counter() - t)
        return min(times), out

    best_of_two(singles[:1024])  # compiles the grouped stack once
    t_small, _ = best_of_two(singles[:1000])
    t_stack, stacked = best_of_two(singles)
    assert t_arrays < 3.0 and t_stack < 10.0, (t_arrays, t_stack)
    assert t_stack < 25.0 * t_small + 0.2, (t_small, t_stack)
    for x, y in zip(jax.tree_util.tree_leaves(batched), jax.tree_util.tree_leaves(stacked),
                    strict=True):
        np.testing.assert_array_equal(x, y)


def test_simulate_settings_batches_rotations_with_one_batched_mount():
    from lidarjax.io import Settings
    from lidarjax.workflows.seed_tables import settings_mount, settings_mounts, simulate_settings

    betas = [0.0, 45.0, 90.0, 135.0, 180.0]
    locations = np.array([[2.0, 1.0, 31.0], [3.0, 0.0, 31.0], [4.0, -1.0, 31.0],
                          [5.0, -2.0, 31.0], [6.0, -3.0, 31.0]])
    settings = Settings(zone=2, verbose=1, height=90.0, nh=3, gamma=5.0, beta=0.0, psi=180.0,
                        epsilon=21.0, betas=np.array(betas), locations=locations)
    mount = settings_mount(settings, betas, pitch=1.0)
    assert mount.batch_shape == (5,)
    for m, one in zip(mount, settings_mounts(settings, betas, pitch=1.0), strict=True):
        for x, y in zip(jax.tree_util.tree_leaves(m), jax.tree_util.tree_leaves(one), strict=True):
            np.testing.assert_array_equal(x, y)
    fields = {b: lj.GridField.from_function(
        lj.scenes.hill(height=30.0, half_width=150.0, speed=9.0, direction=250.0 + b).sample,
        X, Y, Z) for b in betas}
    scan = lj.windcube_v1()
    whole = simulate_settings(settings, betas, fields.__getitem__, scan, pitch=1.0)
    chunked = simulate_settings(settings, betas, fields.__getitem__, scan, pitch=1.0,
                                batch_size=2)  # 2 + 2 + 1 (padded to 2)
    assert list(whole) == list(chunked) == betas
    # the per-mount results are those of simulate_rotations (itself checked against
    # simulate above), whatever the batching
    ref = lj.simulate_rotations([fields[b] for b in betas], scan, list(mount), settings.heights(),
                                u_refs=(-15.0, 0.0, 0.0))
    for k, b in enumerate(betas):
        for x, y, z in zip(jax.tree_util.tree_leaves(whole[b]),
                           jax.tree_util.tree_leaves(chunked[b]),
                           jax.tree_util.tree_leaves(ref), strict=True):
            np.testing.assert_array_equal(x, np.asarray(z)[k])
            np.testing.assert_allclose(y, x, rtol=1e-13, atol=1e-13)
    with pytest.raises(ValueError, match="batch_size"):
        simulate_settings(settings, betas, fields.__getitem__, scan, batch_size=0)
