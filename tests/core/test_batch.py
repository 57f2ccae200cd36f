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
