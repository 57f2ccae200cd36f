"""How the lidar sits in the CFD frame: location, the seed's four angles and the tilt."""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._precision import default_float, is_concrete, split

__all__ = ["Mount"]


class Mount(eqx.Module):
    """The lidar's mounting, in degrees and metres (all dynamic and differentiable).

    **Arguments:**

    - `location`: ``(3,)`` lidar position (beam origin) in CFD coordinates, metres. Concrete
      inputs are kept to float64 accuracy even in float32 (as a rounded value plus residual),
      so UTM-sized coordinates work in float32.
    - `beta`: platform rotation relative to the CFD axes (the seed's beta: the angle between
      the free-stream wind vector and the rig), degrees.
    - `gamma`: angle between the lidar and the rig (platform), degrees.
    - `psi`: rotation between the CFD and lidar coordinate systems (180 when the CFD ``+x``
      points upstream, as in the seed), degrees.
    - `epsilon`: the instrument's software north offset, degrees; reconstructed vectors are
      rotated by ``-epsilon`` into the north frame.
    - `pitch`, `roll`: the installation's tilt, degrees. A vector in the lidar's body frame
      (``x`` towards S1, ``y`` towards S0, ``z`` along the instrument axis) maps to the level
      lidar frame by ``T = R_x(pitch) @ R_y(roll)``, with
      ``R_x(a) = [[1, 0, 0], [0, cos a, -sin a], [0, sin a, cos a]]`` and
      ``R_y(b) = [[cos b, 0, sin b], [0, 1, 0], [-sin b, 0, cos b]]``. So positive pitch
      raises the S0 (``+y``) side, and positive roll lowers the S1 (``+x``) side. The level
      lidar frame then goes through the chain above unchanged (beta, gamma, psi to CFD;
      epsilon to north). Beams focus at range ``h / cos(cone)`` along the tilted beams (the
      instrument assumes a level mount), the vertical beam at ``h``; the point reference and
      the free stream stay level. Whether the reconstruction knows the tilt is the scan's
      `tilt_compensation`. A forward-looking nacelle lidar is the same chain:
      ``pitch = -90`` points the instrument axis along the lidar's ``+y`` (then ``heights``
      are distances along that axis).

    See `lidarjax.frames` for the chain these angles define.
    """

    location: Float[Array, 3]
    location_lo: Float[Array, 3]
    beta: Float[Array, ""]
    gamma: Float[Array, ""]
    psi: Float[Array, ""]
    epsilon: Float[Array, ""]
    pitch: Float[Array, ""]
    roll: Float[Array, ""]

    def __init__(
        self,
        location: Float[ArrayLike, 3],
        beta: Float[ArrayLike, ""] = 0.0,
        gamma: Float[ArrayLike, ""] = 0.0,
        psi: Float[ArrayLike, ""] = 0.0,
        epsilon: Float[ArrayLike, ""] = 0.0,
        pitch: Float[ArrayLike, ""] = 0.0,
        roll: Float[ArrayLike, ""] = 0.0,
    ):
        angles = {"beta": beta, "gamma": gamma, "psi": psi, "epsilon": epsilon,
                  "pitch": pitch, "roll": roll}
        if is_concrete(location, *angles.values()):
            loc = np.asarray(location, dtype=np.float64)
            if loc.shape != (3,):
                raise ValueError(
                    f"Mount: `location` must be (x, y, z) in CFD metres, shape (3,); got "
                    f"shape {loc.shape}."
                )
            if not np.all(np.isfinite(loc)):
                raise ValueError(f"Mount: `location` must be finite, got {loc.tolist()}.")
            for name, val in angles.items():
                a = np.asarray(val, dtype=np.float64)
                if a.shape != () or not np.isfinite(a):
                    raise ValueError(
                        f"Mount: `{name}` must be one finite angle in degrees, got {val!r}."
                    )
        dtype = _dtype_of(location)
        self.location, self.location_lo = split(location, dtype)
        self.beta, self.gamma, self.psi, self.epsilon, self.pitch, self.roll = (
            jnp.asarray(a, dtype=_dtype_of(a)) for a in angles.values()
        )


def _dtype_of(value):
    """Keep a JAX/numpy float input's dtype; Python numbers get the default float."""
    dt = getattr(value, "dtype", None)
    if dt is not None and jnp.issubdtype(dt, jnp.floating):
        return dt if dt != np.float64 else default_float()
    return default_float()
