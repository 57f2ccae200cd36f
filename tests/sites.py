"""Synthetic sites shared by the inverse-problem tests.

A hemisphere of radius 20 m (`lidarjax.scenes.hemisphere`, potential flow) stands in for a
platform; a Windcube V2 sits on its flank, 12.6 m off its top (uncorrected errors of 2 to 12 %
in speed and up to 1.5 degrees in direction), with a software north offset of 10
degrees so that CFD and north frames differ. Tables and records are cached so that every
test module shares the compiled forward model.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

import lidarjax as lj
from lidarjax._precision import host_array
from lidarjax.angles import heading
from lidarjax.scenes import hemisphere

RADIUS = 20.0
HEIGHTS = (5.0, 10.0, 20.0, 40.0)
EPSILON = 10.0  # software north offset: north-frame direction = CFD direction + EPSILON
MOUNT = lj.Mount([12.0, -4.0, float(np.sqrt(RADIUS**2 - 160.0))], epsilon=EPSILON)
SCAN = lj.windcube_v2()


def scene(direction, speed=10.0):
    """The hemisphere with a free stream of `speed` m/s from CFD `direction` degrees."""
    return hemisphere(radius=RADIUS, speed=speed, direction=direction)


@jax.jit
def simulate_at(direction, speed):
    """`lidarjax.simulate` for one run; vmappable over (direction, speed)."""
    return lj.simulate(
        scene(direction, speed), SCAN, MOUNT, jnp.asarray(HEIGHTS), u_ref=speed * heading(direction)
    )


@jax.jit
def _records(d, u):
    return jax.vmap(simulate_at)(d, u)


def records(cfd_directions, speeds):
    """Simulations (leading record axis) at CFD directions (degrees) and speeds (m/s).

    Batches are padded to a power of two (at least 32) so that few shapes get compiled."""
    d = np.atleast_1d(np.asarray(cfd_directions, np.float64))
    u = np.broadcast_to(np.asarray(speeds, np.float64), d.shape)
    n = d.shape[0]
    m = max(32, 1 << (n - 1).bit_length())
    pad = lambda a: np.concatenate([a, np.full(m - n, a[0])])  # noqa: E731
    out = _records(jnp.asarray(pad(d)), jnp.asarray(pad(u)))
    # cropped on the host and moved back in one transfer: an eager slice, or `jnp.asarray` of
    # each leaf, compiles once per length and output (~30 and ~77 programs)
    return host_array(jax.tree_util.tree_map(lambda a: np.asarray(a)[:n], out))


@functools.cache
def table(sector: float = 30.0, first: float = 0.0, fields: bool = False) -> lj.ResponseTable:
    """A table of runs every `sector` degrees (CFD frame) from `first`."""
    cfd = first + np.arange(0.0, 360.0, sector)
    sims = records(cfd, 10.0)
    kwargs = {}
    if fields:
        kwargs["fields"] = [scene(float(d)) for d in cfd]
    return lj.ResponseTable.from_simulations(sims, mount=MOUNT, **kwargs)
