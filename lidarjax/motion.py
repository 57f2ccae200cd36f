"""Platform motion: the lidar's position and attitude as functions of time.

A floating lidar (buoy, ship, floating turbine) moves while it scans. A motion gives, at
times ``t`` (seconds, any shape):

- the lidar's displacement from its `lidarjax.Mount` location, in metres, in the lidar
  frame of the mount at rest: **sway** along ``+x`` (towards beam S1), **surge** along
  ``+y`` (towards beam S0), **heave** along ``+z`` (up);
- its velocity, m/s, same frame (the LOS of a moving lidar is ``n . (V_air - v_lidar)``:
  the Doppler shift is relative to the instrument);
- its attitude change in degrees: **pitch** and **roll** add to `Mount.pitch` and
  `Mount.roll` (the tilt of `lidarjax.frames`, same conventions), **yaw** adds to
  `Mount.gamma` (the lidar's rotation on its platform, same sense).

Two kinds, both `equinox` modules with every number dynamic and differentiable:

- `SampledMotion`: logged motion (times and values, e.g. a buoy's motion CSV read by
  `lidarjax.io.read_motion_csv`), linearly interpolated; the velocity is the derivative of
  the interpolant of central differences (the logged displacement's own derivative).
  Outside the logged times the state is NaN, so those LOS are unavailable (never a clamp).
- `SinusoidalMotion`: each degree of freedom ``a sin(2 pi t / T + phi)``, exact velocity.

Rotational motion moves the beams, not the lidar: the lidar is taken at the rotation centre
(no lever arm), so only the translation gives the lidar a velocity.
"""

from __future__ import annotations

import abc

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ._precision import default_float, is_concrete

__all__ = ["AbstractMotion", "SampledMotion", "SinusoidalMotion", "DOF"]

#: Degrees of freedom, in the order of `SinusoidalMotion`'s arrays and of the motion CSV.
DOF = ("surge", "sway", "heave", "pitch", "roll", "yaw")


class AbstractMotion(eqx.Module):
    """Interface: `state(t) -> (offset, velocity, attitude)`, each ``t.shape + (3,)``:
    offset ``(sway, surge, heave)`` m and velocity m/s in the lidar frame at rest (x, y, z),
    attitude ``(pitch, roll, yaw)`` degrees."""

    @abc.abstractmethod
    def state(self, t):
        """Offset (m), velocity (m/s) and attitude (degrees) at times `t` (s)."""


def _f(value, dtype=None):
    a = jnp.asarray(value)
    if not jnp.issubdtype(a.dtype, jnp.floating):
        a = a.astype(dtype or default_float())
    return a


class SinusoidalMotion(AbstractMotion):
    """Each degree of freedom a sinusoid ``amplitude * sin(2 pi t / period + phase)``.

    **Arguments** (each a number or ``(6,)`` in the order `DOF` = surge, sway, heave (m),
    pitch, roll, yaw (degrees)): `amplitude`, `period` (s, positive), `phase` (radians).
    Use `SinusoidalMotion.of(pitch=(2.0, 8.0))` to name degrees of freedom as
    ``(amplitude, period[, phase])``.
    """

    amplitude: Float[Array, " 6"]
    period: Float[Array, " 6"]
    phase: Float[Array, " 6"]

    def __init__(self, amplitude, period, phase=0.0):
        amplitude, period, phase = (jnp.broadcast_to(_f(a), (6,)) for a in (amplitude, period, phase))
        if is_concrete(period) and not np.all(np.asarray(period) > 0):
            raise ValueError(f"SinusoidalMotion: periods must be positive seconds, got "
                             f"{np.asarray(period).tolist()}.")
        self.amplitude, self.period, self.phase = amplitude, period, phase

    @classmethod
    def of(cls, **dofs) -> SinusoidalMotion:
        """Named degrees of freedom: ``of(roll=(2.0, 10.0), heave=(0.5, 6.0, 0.3))`` gives
        roll of 2 degrees amplitude and 10 s period, heave 0.5 m at 6 s with phase 0.3 rad."""
        amp, per, pha = np.zeros(6), np.ones(6), np.zeros(6)
        for name, spec in dofs.items():
            if name not in DOF:
                raise ValueError(f"SinusoidalMotion.of: unknown degree of freedom {name!r}; "
                                 f"choose from {DOF}.")
            spec = tuple(spec)
            if len(spec) not in (2, 3):
                raise ValueError(f"SinusoidalMotion.of: {name} needs (amplitude, period[, phase]),"
                                 f" got {spec}.")
            i = DOF.index(name)
            amp[i], per[i] = spec[0], spec[1]
            pha[i] = spec[2] if len(spec) == 3 else 0.0
        return cls(amp, per, pha)

    def state(self, t):
        t = jnp.asarray(t)[..., None]
        w = 2 * jnp.pi / self.period
        x = self.amplitude * jnp.sin(w * t + self.phase)
        dx = self.amplitude * w * jnp.cos(w * t + self.phase)
        # DOF order surge (y), sway (x), heave (z) -> lidar frame (x, y, z)
        offset = jnp.stack([x[..., 1], x[..., 0], x[..., 2]], axis=-1)
        velocity = jnp.stack([dx[..., 1], dx[..., 0], dx[..., 2]], axis=-1)
        return offset, velocity, x[..., 3:6]


class SampledMotion(AbstractMotion):
    """Logged motion: values at increasing `times`, linearly interpolated.

    **Arguments:** `times` ``(n,)`` seconds, increasing (at least 2); `offset` ``(n, 3)``
    metres ``(sway, surge, heave)`` in the lidar frame at rest (x, y, z); `attitude`
    ``(n, 3)`` degrees ``(pitch, roll, yaw)``. Either may be None (zero).

    Raises `ValueError` for shapes that disagree or times not strictly increasing.
    """

    times: Float[Array, " n"]
    offset: Float[Array, "n 3"]
    attitude: Float[Array, "n 3"]

    def __init__(self, times, offset=None, attitude=None):
        times = _f(times)
        n = times.shape[0] if times.ndim == 1 else -1
        offset = jnp.zeros((max(n, 0), 3), times.dtype) if offset is None else _f(offset, times.dtype)
        attitude = (jnp.zeros((max(n, 0), 3), times.dtype) if attitude is None
                    else _f(attitude, times.dtype))
        if is_concrete(times, offset, attitude):
            t = np.asarray(times, np.float64)
            if t.ndim != 1 or t.size < 2 or not np.all(np.diff(t) > 0) or not np.all(np.isfinite(t)):
                raise ValueError("SampledMotion: `times` must be at least 2 finite, strictly "
                                 "increasing seconds.")
            for name, a in (("offset", offset), ("attitude", attitude)):
                if a.shape != (t.size, 3):
                    raise ValueError(f"SampledMotion: `{name}` must be shaped ({t.size}, 3), got "
                                     f"{a.shape}.")
        self.times, self.offset, self.attitude = times, offset, attitude

    def state(self, t):
        t = jnp.asarray(t, self.times.dtype)
        inside = (t >= self.times[0]) & (t <= self.times[-1])

        def interp(values):
            cols = [jnp.interp(t, self.times, values[:, k]) for k in range(3)]
            return jnp.where(inside[..., None], jnp.stack(cols, axis=-1), jnp.nan)

        rate = jnp.gradient(self.offset, self.times, axis=0)
        return interp(self.offset), interp(rate), interp(self.attitude)
