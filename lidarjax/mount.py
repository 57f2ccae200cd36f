"""How the lidar sits in the CFD frame: location and the seed's four angles."""

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

    See `lidarjax.frames` for the chain these angles define.
    """

    location: Float[Array, 3]
    location_lo: Float[Array, 3]
    beta: Float[Array, ""]
    gamma: Float[Array, ""]
    psi: Float[Array, ""]
    epsilon: Float[Array, ""]

    def __init__(
        self,
        location: Float[ArrayLike, 3],
        beta: Float[ArrayLike, ""] = 0.0,
        gamma: Float[ArrayLike, ""] = 0.0,
        psi: Float[ArrayLike, ""] = 0.0,
        epsilon: Float[ArrayLike, ""] = 0.0,
    ):
        if is_concrete(location, beta, gamma, psi, epsilon):
            loc = np.asarray(location, dtype=np.float64)
            if loc.shape != (3,):
                raise ValueError(
                    f"Mount: `location` must be (x, y, z) in CFD metres, shape (3,); got "
                    f"shape {loc.shape}."
                )
            if not np.all(np.isfinite(loc)):
                raise ValueError(f"Mount: `location` must be finite, got {loc.tolist()}.")
            for name, val in (("beta", beta), ("gamma", gamma), ("psi", psi), ("epsilon", epsilon)):
                a = np.asarray(val, dtype=np.float64)
                if a.shape != () or not np.isfinite(a):
                    raise ValueError(
                        f"Mount: `{name}` must be one finite angle in degrees, got {val!r}."
                    )
        dtype = _dtype_of(location)
        self.location, self.location_lo = split(location, dtype)
        self.beta, self.gamma, self.psi, self.epsilon = (
            jnp.asarray(a, dtype=_dtype_of(a)) for a in (beta, gamma, psi, epsilon)
        )


def _dtype_of(value):
    """Keep a JAX/numpy float input's dtype; Python numbers get the default float."""
    dt = getattr(value, "dtype", None)
    if dt is not None and jnp.issubdtype(dt, jnp.floating):
        return dt if dt != np.float64 else default_float()
    return default_float()
