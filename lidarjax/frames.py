"""The frame chain, written once and used for positions and velocities alike.

Frames (all right-handed, ``z`` up, metres and m/s):

- **CFD frame**: the coordinates of the field (a grid or an analytic scene).
- **Body frame**: the instrument's own axes: ``+x`` towards beam S1, ``+y`` towards beam S0,
  ``+z`` along the instrument axis. Scans (`lidarjax.Scan`) define their beams in it.
- **Lidar frame** (the level lidar frame): origin at the lidar, ``+y`` towards beam S0
  (azimuth 0) and ``+x`` towards beam S1 (azimuth 90, clockwise from ``+y`` seen from above)
  as they would point on a level mount, ``+z`` up. For a level mount it is the body frame.
- **North frame**: the lidar frame rotated by the instrument's software north offset
  ``epsilon``; reconstructed, point and free-stream vectors are reported in it.

Rotations are about ``z``, positive anticlockwise seen from above (the seed's
equation 13): ``R(t) = [[cos t, -sin t, 0], [sin t, cos t, 0], [0, 0, 1]]``.

The chain (angles of `lidarjax.Mount`, degrees):

- body -> lidar (the installation's tilt): ``T = R_x(pitch) @ R_y(roll)`` with
  ``R_x(a) = [[1, 0, 0], [0, cos a, -sin a], [0, sin a, cos a]]`` and
  ``R_y(b) = [[cos b, 0, sin b], [0, 1, 0], [-sin b, 0, cos b]]``: positive pitch raises the
  S0 (``+y``) side, positive roll lowers the S1 (``+x``) side. ``pitch = -90`` points the
  instrument axis along the lidar's ``+y`` (a forward-looking nacelle lidar: mount it with
  ``+y`` along the nacelle axis); the body ``+x`` stays the lidar's ``+x``. Beams keep their
  focus ranges ``h / cos(cone)`` along the tilted directions (the instrument assumes it is
  level); the point reference and the free stream stay level;
- velocity CFD -> lidar: rotate by ``psi``, then by ``-(beta + gamma)``, i.e.
  ``v_lidar = R(psi - beta - gamma) v_cfd``;
- position lidar -> CFD: the exact inverse, ``p_cfd = R(beta + gamma - psi) p_lidar + location``;
- lidar -> north: ``v_north = R(-epsilon) v_lidar``.

The seed UDF rotates positions by ``R(beta + gamma) R(psi)`` instead of the inverse of its
velocity rotation; the two agree only for ``psi`` equal to 0 or 180 degrees (rotations about
one axis commute, so its chain is ``R(beta + gamma + psi)``). lidarjax uses the consistent
chain for every ``psi``.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._precision import HIGHEST
from ._util import compiled

__all__ = [
    "rotation_x",
    "rotation_y",
    "rotation_z",
    "tilt_rotation",
    "body_to_cfd_rotation",
    "lidar_to_cfd_rotation",
    "cfd_to_lidar_rotation",
    "lidar_to_north_rotation",
    "cfd_to_north_rotation",
    "beam_directions",
    "rotate",
]


def _cos_sin(angle_deg):
    """``cos``, ``sin`` of `angle_deg` degrees and the zeros and ones of its shape."""
    t = jnp.deg2rad(jnp.asarray(angle_deg))
    return jnp.cos(t), jnp.sin(t), jnp.zeros_like(t), jnp.ones_like(t)


def _matrix(*rows):
    """A ``3 x 3`` matrix (leading axes of the entries last) from its rows of entries."""
    return jnp.stack([jnp.stack(row) for row in rows])


def rotation_z(angle_deg: Float[ArrayLike, ""]) -> Float[Array, "3 3"]:
    """Rotation matrix about ``z`` by `angle_deg` degrees, anticlockwise seen from above."""
    c, s, o, i = _cos_sin(angle_deg)
    return _matrix((c, -s, o), (s, c, o), (o, o, i))


def rotation_x(angle_deg: Float[ArrayLike, ""]) -> Float[Array, "3 3"]:
    """``R_x(a) = [[1, 0, 0], [0, cos a, -sin a], [0, sin a, cos a]]`` for `angle_deg` degrees
    (rotates ``+y`` towards ``+z``)."""
    c, s, o, i = _cos_sin(angle_deg)
    return _matrix((i, o, o), (o, c, -s), (o, s, c))


def rotation_y(angle_deg: Float[ArrayLike, ""]) -> Float[Array, "3 3"]:
    """``R_y(b) = [[cos b, 0, sin b], [0, 1, 0], [-sin b, 0, cos b]]`` for `angle_deg` degrees
    (rotates ``+z`` towards ``+x``)."""
    c, s, o, i = _cos_sin(angle_deg)
    return _matrix((c, o, s), (o, i, o), (-s, o, c))


def tilt_rotation(
    pitch_deg: Float[ArrayLike, ""], roll_deg: Float[ArrayLike, ""]
) -> Float[Array, "3 3"]:
    """The installation's tilt, body -> level lidar frame: ``T = R_x(pitch) @ R_y(roll)``
    (degrees). Positive pitch raises the S0 (``+y``) side, positive roll lowers the S1
    (``+x``) side; ``pitch = -90`` points the instrument axis along the lidar's ``+y``."""
    return jnp.matmul(rotation_x(pitch_deg), rotation_y(roll_deg), precision=HIGHEST)


def body_to_cfd_rotation(mount) -> Float[Array, "3 3"]:
    """Beam directions body -> CFD frame: ``R(beta + gamma - psi) @ T(pitch, roll)``."""
    return jnp.matmul(lidar_to_cfd_rotation(mount), tilt_rotation(mount.pitch, mount.roll),
                      precision=HIGHEST)


def rotate(matrix: Float[Array, "3 3"], vectors: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """Apply a ``3x3`` rotation to ``(..., 3)`` vectors.

    Written as three multiply-adds per component rather than a matrix product: XLA fuses
    them with the producer and consumer of the vectors, where a ``dot`` over millions of
    3-vectors runs as a separate, much slower kernel on the CPU."""
    m = jnp.asarray(matrix)
    v = jnp.asarray(vectors)
    x, y, z = v[..., 0], v[..., 1], v[..., 2]
    return jnp.stack([m[i, 0] * x + m[i, 1] * y + m[i, 2] * z for i in range(3)], axis=-1)


def lidar_to_cfd_rotation(mount) -> Float[Array, "3 3"]:
    """Rotation taking lidar-frame positions (and vectors) to the CFD frame: ``R(beta+gamma-psi)``."""
    return rotation_z(mount.beta + mount.gamma - mount.psi)


def cfd_to_lidar_rotation(mount) -> Float[Array, "3 3"]:
    """Rotation taking CFD-frame velocities to the lidar frame: ``R(psi - beta - gamma)``."""
    return rotation_z(mount.psi - mount.beta - mount.gamma)


def lidar_to_north_rotation(mount) -> Float[Array, "3 3"]:
    """The instrument's software rotation, lidar -> north frame: ``R(-epsilon)``."""
    return rotation_z(-mount.epsilon)


def cfd_to_north_rotation(mount) -> Float[Array, "3 3"]:
    """CFD-frame velocities to the north frame: ``R(-epsilon) R(psi - beta - gamma)``."""
    return rotation_z(mount.psi - mount.beta - mount.gamma - mount.epsilon)


@compiled
def beam_directions(
    azimuth_deg: Float[ArrayLike, " b"], cone_deg: Float[ArrayLike, " b"]
) -> Float[Array, "b 3"]:
    """Beam unit vectors in the lidar frame: ``(sin c sin a, sin c cos a, cos c)``.

    `azimuth_deg` is clockwise from the lidar's ``+y`` (beam S0); `cone_deg` is the angle
    from the vertical (0 for a vertical beam).
    """
    a = jnp.deg2rad(jnp.asarray(azimuth_deg))
    c = jnp.deg2rad(jnp.asarray(cone_deg))
    sc = jnp.sin(c)
    return jnp.stack([sc * jnp.sin(a), sc * jnp.cos(a), jnp.cos(c)], axis=-1)
