"""The inflow of the lidar-assisted-control spectra: IEC 61400-1 Kaimal spectra of u, v, w and
the IEC exponential coherence of u (Task 52's analytic model, Schlipf 2015 §5).

Frame: ``u`` is the longitudinal component along the mean wind (m/s), ``v`` lateral, ``w``
vertical. Frequencies ``f`` are in Hz, one-sided spectra in (m/s)^2/Hz.
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

__all__ = ["IEC_REFERENCE_INTENSITY", "KaimalInflow", "iec_turbulence_intensity"]

#: IEC 61400-1 reference turbulence intensity ``I_ref`` of the classes A+, A, B, C.
IEC_REFERENCE_INTENSITY = {"A+": 0.18, "A": 0.16, "B": 0.14, "C": 0.12}


def iec_turbulence_intensity(mean_speed, turbulence_class: str = "B"):
    """The normal turbulence model's intensity ``I_ref (0.75 U + 5.6) / U`` (IEC 61400-1 ed. 3).

    **Arguments:**

    - `mean_speed`: hub-height mean wind speed ``U`` (m/s).
    - `turbulence_class`: ``"A+"``, ``"A"``, ``"B"`` or ``"C"``.

    **Returns:** the turbulence intensity ``sigma_u / U`` (dimensionless).
    """
    if turbulence_class not in IEC_REFERENCE_INTENSITY:
        raise ValueError(f"iec_turbulence_intensity: turbulence_class={turbulence_class!r} is not one of "
                         f"{sorted(IEC_REFERENCE_INTENSITY)}")
    u = jnp.asarray(mean_speed)
    return IEC_REFERENCE_INTENSITY[turbulence_class] * (0.75 * u + 5.6) / u


def _positive(name, value, owner="KaimalInflow", *, allow_zero=False):
    """`value` as a floating scalar array; a concrete one must be finite and positive (or
    zero with `allow_zero`), else a ValueError naming `owner` and `name`."""
    value = jnp.asarray(value)
    if not jnp.issubdtype(value.dtype, jnp.floating):
        value = value.astype(jnp.asarray(0.0).dtype)
    if not isinstance(value, jnp.ndarray) or value.ndim:
        raise ValueError(f"{owner}: {name} must be a scalar, got shape {value.shape}")
    try:
        v = float(value)
        bad = not (v >= 0 if allow_zero else v > 0) or not np.isfinite(v)
    except Exception:  # a tracer: cannot check, keep it
        bad = False
    if bad:
        kind = "non-negative" if allow_zero else "positive"
        raise ValueError(f"{owner}: {name} must be a finite {kind} number, got {float(value)}")
    return value


class KaimalInflow(eqx.Module):
    """IEC 61400-1 Kaimal turbulence with the IEC exponential coherence of ``u``.

    Spectra ``S_k(f) = 4 sigma_k^2 (L_k/U) / (1 + 6 f L_k / U)^(5/3)`` with
    ``sigma_v = 0.8 sigma_u``, ``sigma_w = 0.5 sigma_u``, ``L_u = 8.1 Lambda_1``,
    ``L_v = 2.7 Lambda_1``, ``L_w = 0.66 Lambda_1``; coherence of ``u`` between points a
    lateral-vertical distance ``r`` apart ``exp(-a sqrt((f r / U)^2 + (0.12 r / L_c)^2))``,
    ``L_c = 8.1 Lambda_1``, ``a = 12``. Turbulence is frozen (Taylor): a point ``x`` upstream of
    the rotor sees the wind ``x / U`` earlier.

    **Arguments:**

    - `mean_speed`: hub-height mean wind speed ``U`` (m/s).
    - `turbulence_intensity`: ``sigma_u / U`` (dimensionless); see `iec_turbulence_intensity`.
    - `length_scale`: the IEC longitudinal turbulence scale parameter ``Lambda_1`` (m),
      42 m above 60 m hub height.
    - `coherence_decay`: the coherence decay ``a`` (dimensionless), 12 in IEC 61400-1 ed. 3.

    Every number is dynamic and differentiable.
    """

    mean_speed: Float[Array, ""]
    turbulence_intensity: Float[Array, ""]
    length_scale: Float[Array, ""]
    coherence_decay: Float[Array, ""]

    def __init__(self, mean_speed: Float[ArrayLike, ""], turbulence_intensity: Float[ArrayLike, ""],
                 length_scale: Float[ArrayLike, ""] = 42.0, coherence_decay: Float[ArrayLike, ""] = 12.0):
        self.mean_speed = _positive("mean_speed", mean_speed)
        self.turbulence_intensity = _positive("turbulence_intensity", turbulence_intensity)
        self.length_scale = _positive("length_scale", length_scale)
        self.coherence_decay = _positive("coherence_decay", coherence_decay)

    @property
    def sigma_u(self) -> Float[Array, ""]:
        """Standard deviation of ``u`` (m/s)."""
        return self.turbulence_intensity * self.mean_speed

    def spectra(self, f: Float[ArrayLike, " f"]) -> Float[Array, "3 f"]:
        """Kaimal one-sided spectra of ``u``, ``v``, ``w`` at frequencies `f` (Hz), (m/s)^2/Hz."""
        f = jnp.asarray(f)
        u = self.mean_speed
        sig = self.sigma_u * jnp.array([1.0, 0.8, 0.5], f.dtype)
        scale = self.length_scale * jnp.array([8.1, 2.7, 0.66], f.dtype)
        return (4 * sig[:, None] ** 2 * scale[:, None] / u
                / (1 + 6 * f[None] * scale[:, None] / u) ** (5 / 3))

    def decay_rate(self, f: Float[ArrayLike, " f"]) -> Float[Array, " f"]:
        """``a sqrt((f/U)^2 + (0.12/L_c)^2)`` (1/m): the coherence is ``exp(-rate * r)``."""
        f = jnp.asarray(f)
        lc = 8.1 * self.length_scale
        return self.coherence_decay * jnp.sqrt((f / self.mean_speed) ** 2 + (0.12 / lc) ** 2)
