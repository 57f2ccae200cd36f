"""Probe nodes for the resolution where the beam is (`lidarjax.probe_for_field` with a mount):
on a grid graded to 0.5 m at the ground and 6 m aloft, each height gets the nodes its beams'
support needs, not the ground's, and still integrates the weighting within the 0.01
transfer-function criterion (checked against a dense-node reference on a flow that is smooth
on the local grid scale, the content a graded CFD mesh resolves)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import lidarjax as lj
from lidarjax.beam import GradedProbe
from lidarjax.probe import TRANSFER_TOL

HEIGHTS = np.array([10.0, 40.0, 120.0])


def _graded_axis():
    """0.5 m at the ground, growing 12 % per cell to 6 m, up to 260 m."""
    dz = [0.5]
    while sum(dz) < 260.0:
        dz.append(min(dz[-1] * 1.12, 6.0))
    return np.concatenate([[0.0], np.cumsum(dz)])


@pytest.fixture(scope="module")
def setup():
    z = _graded_axis()
    x = np.arange(-104.0, 104.1, 8.0)
    # a wave 16 local cells long in z (the phase advances pi/8 per cell), on a 10 m/s wind.
    # Shorter waves put more of their trilinear interpolant's kinks (images at 2 pi / dz - k,
    # relative amplitude ~ (k dz / 2 pi)^2) beyond the Nyquist wavenumber the criterion
    # covers, on uniform grids as on graded ones: 8 cells give 0.017 at 120 m with the 13
    # nodes a uniform 6 m grid gets too
    phase = np.arange(z.size) * np.pi / 8
    vel = np.zeros((x.size, x.size, z.size, 3))
    vel[..., 0] = 10.0 + np.sin(phase)
    vel[..., 1] = 2.0
    vel[..., 2] = np.cos(phase)
    field = lj.GridField(x, x, z, vel)
    scan, mount = lj.windcube_v2(), lj.Mount([0.0, 0.0, 0.0])
    probe = lj.probe_for_field(field, scan, HEIGHTS, lj.PulsedProbe(), mount=mount)
    return field, scan, mount, probe


def test_node_count_follows_the_spacing_along_the_support(setup):
    field, scan, mount, probe = setup
    assert field.resolution == 0.5
    every = lj.probe_for_field(field, scan, HEIGHTS, lj.PulsedProbe())  # finest spacing anywhere
    assert every.n_nodes > 90  # the ground's 0.5 m: ~100 nodes at every height
    assert isinstance(probe, GradedProbe)
    counts = probe.node_counts
    assert len(counts) == HEIGHTS.size
    # at 40 m the weight sits where cells are 2-6 m: far fewer nodes than the ground needs
    assert counts[1] < every.n_nodes / 1.5
    # at 120 m the support sees only 6 m cells: what a uniform 6 m grid needs (at the
    # share of the tolerance left for coarse cells), not more
    uniform = lj.probe_for_spacing(lj.PulsedProbe(), 6.0, HEIGHTS[2:] / np.cos(np.radians(28.0)),
                                   tol=TRANSFER_TOL / 4)
    assert counts[2] <= uniform.n_nodes < counts[1]
    # the same choice with the mount in a batch of rotations, and memoised
    rot = lj.stack_mounts([lj.Mount([0.0, 0.0, 0.0], beta=b) for b in (0.0, 90.0)])
    again = lj.probe_for_field(field, scan, HEIGHTS, lj.PulsedProbe(), mount=rot)
    assert again.node_counts == counts
    # uniform grids and explicit counts are untouched
    flat = lj.GridField(field.x, field.y, np.linspace(0.0, 260.0, 53), np.zeros((27, 27, 53, 3)))
    plain = lj.probe_for_field(flat, scan, HEIGHTS, lj.PulsedProbe(), mount=mount)
    assert isinstance(plain, lj.PulsedProbe) and plain.n_nodes == lj.probe_for_field(
        flat, scan, HEIGHTS, lj.PulsedProbe()).n_nodes
    fixed = lj.PulsedProbe(n_nodes=21)
    assert lj.probe_for_field(field, scan, HEIGHTS, fixed, mount=mount) is fixed


def test_graded_nodes_agree_with_a_dense_reference(setup):
    """Every height within 0.01 (the transfer-function criterion, times the wave's unit
    amplitude) of 601 nodes; the same numbers through `simulate` (which grades by itself)
    and `simulate_rotations`."""
    field, scan, mount, probe = setup
    ref = lj.simulate(field, scan, mount, HEIGHTS, probe=lj.PulsedProbe(n_nodes=601),
                      point_reference=False)
    sim = lj.simulate(field, scan, mount, HEIGHTS, probe=lj.PulsedProbe(), point_reference=False)
    err = np.abs(np.asarray(sim.los - ref.los)).max(axis=1)
    assert np.all(err < TRANSFER_TOL), err
    given = lj.simulate(field, scan, mount, HEIGHTS, probe=probe, point_reference=False)
    np.testing.assert_array_equal(np.asarray(given.los), np.asarray(sim.los))
    rots = lj.simulate_rotations(field, scan, [mount, mount], HEIGHTS, probe=lj.PulsedProbe(),
                                 point_reference=False)
    np.testing.assert_allclose(np.asarray(rots.los[1]), np.asarray(sim.los), rtol=0, atol=1e-12)


def test_beam_points_hold_the_graded_nodes(setup):
    """`beam_points` lists the nodes each height samples (its own count; the padding of
    `GradedProbe.nodes` sits at the focus), so an exact sampler prepared there is exact."""
    field, scan, mount, probe = setup
    pts = lj.beam_points(field, scan, mount, HEIGHTS, lj.PulsedProbe())
    n_cfd = np.asarray(scan.directions())  # level mount at beta 0: lidar frame = CFD frame
    for i, (rows, p) in enumerate(probe.rows()):
        r = HEIGHTS[rows][:, None] / n_cfd[None, :, 2]
        off = np.asarray(p.nodes(jnp.asarray(r))[0])
        want = (r[..., None] + off)[..., None] * n_cfd[None, :, None, :]
        d = np.linalg.norm(pts[None, :, :] - want.reshape(-1, 1, 3), axis=-1).min(axis=1)
        assert d.max() < 1e-9, i


def test_gradient_through_graded_nodes_is_finite_and_matches_fd(setup):
    field, scan, mount, probe = setup

    def speed(z0):
        m = lj.Mount(jnp.stack([0.0, 0.0, z0]))
        return jnp.sum(lj.simulate(field, scan, m, HEIGHTS, probe=probe,
                                   point_reference=False).lidar_speed)

    g = jax.grad(speed)(0.3)
    fd = (speed(0.3 + 1e-4) - speed(0.3 - 1e-4)) / 2e-4
    assert np.isfinite(g) and abs(g - fd) < 1e-5 * max(1.0, abs(fd))
