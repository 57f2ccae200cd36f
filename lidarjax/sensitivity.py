"""Sensitivity studies and uncertainty budgets through gradients.

`sensitivity` gives the Jacobians of named outputs of `lidarjax.simulate` (what the lidar
reports, the correction factors, the LOS) with respect to named inputs (the installation:
location, heading angles, tilt, cone angle, heights; the free stream; a scene's own
parameters), in physical units, for one mount or a batch of sectors in one compiled call.
`uncertainty` turns them into per-height uncertainty budgets by the GUM law of propagation,
optionally checked by a Monte Carlo of the same function, and carries them through the
inverse (`lidarjax.invert`) to the corrected free stream.

Inputs (names for `wrt` and for `std`), each a perturbation of the nominal configuration:

==================  ======  =================================================================
name                unit    what changes
==================  ======  =================================================================
``x``, ``y``, ``z`` m       the lidar location (CFD frame); ``location`` means all three
``beta``            deg     platform rotation (`lidarjax.Mount`)
``gamma``           deg     lidar-to-platform angle
``psi``             deg     CFD-to-lidar rotation
``epsilon``         deg     software north offset
``pitch``, ``roll`` deg     installation tilt (``T = R_x(pitch) R_y(roll)``, body -> level)
``cone_angle``      deg     the scan's cone angle
``heights``         m       every measurement height shifted by the same amount
``speed``           m/s     free-stream horizontal speed: ``u_ref`` and the field scale
                            together (Reynolds independence): a scene's own ``speed`` /
                            ``speed_ref`` changes, any other field is multiplied by
                            ``speed / speed0``
``direction``       deg     free-stream meteorological direction: ``u_ref`` turns and a
                            scene's own ``direction`` changes (a `GridField`'s inflow is fixed
                            by its CFD run: rotate the platform with ``beta`` instead)
``scene.NAME``      unit    a scene's own parameter by attribute path, optionally indexed:
                            ``scene.radius``, ``scene.half_width``, ``scene.gradient[0,2]``
==================  ======  =================================================================

Outputs (names for `outputs`), per height ``(h,)`` unless noted:

- ``lidar_speed`` (m/s), ``lidar_direction`` (deg), ``lidar_u``, ``lidar_v``, ``lidar_w``
  (m/s, north frame): what the instrument reports; ``lidar_velocity`` ``(h, 3)``;
- ``point_speed``, ``point_direction``: the true wind above the lidar (north frame);
- ``cff_u``, ``cff_v``, ``cff_w``, ``cff_U`` (1), ``cff_th`` (deg): correction factors to the
  free stream (need ``u_ref``, or a scene with its own ``speed`` and ``direction``, whose
  free stream ``speed * heading(direction)`` is then used); ``cfp_*`` to the point;
- ``los`` ``(h, b)`` m/s;
- with a response table (`uncertainty` only): ``inv_speed`` (m/s), ``inv_direction`` (deg), the
  free stream `lidarjax.invert` recovers from the LOS.

Derivatives are exact (forward-mode automatic differentiation, `jax.jacfwd` over the few
inputs, the configuration compiled once); directions are differentiated as continuous
angles (no 0/360 branch), and in Monte Carlo and finite differences their deviations are
wrapped to ``(-180, 180]``. Units of ``jacobian[out][..., i]`` are ``unit(out) per
unit(input i)``: m/s per m, m/s per degree, degrees per degree, ...

Batches: like `lidarjax.simulate_rotations`, `field` may be a list (or stack) of fields and
`mount` a batched `lidarjax.Mount` (e.g. ``Mount(location, beta=betas)``) or a list of
mounts, ``u_ref`` ``(s, 3)``; every result then carries the sector axis ``s`` first.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._backend import default_batch, positive_size
from ._precision import HIGHEST
from ._util import map_in_batches
from .angles import heading, horizontal_speed, wind_direction, wrap180
from .batch import _is_stacked, _n_stacked, rotation_arguments, unstack_field
from .corrections import DEFAULT_RATIO_TOL
from .field import AbstractField, GridField
from .forward import _simulate
from .inverse import invert
from .mount import Mount
from .probe import AbstractProbe
from .response import ResponseTable
from .scan import Scan

__all__ = ["Sensitivity", "Budget", "sensitivity", "uncertainty", "budget_columns", "INPUTS", "OUTPUTS",
           "ANGLE_OUTPUTS"]

#: Named inputs and their units (``scene.*`` paths are also accepted, unit "unit").
INPUTS = {
    "x": "m", "y": "m", "z": "m", "beta": "deg", "gamma": "deg", "psi": "deg",
    "epsilon": "deg", "pitch": "deg", "roll": "deg", "cone_angle": "deg", "heights": "m",
    "speed": "m/s", "direction": "deg",
}
_ALIASES = {"location": ("x", "y", "z")}
_MOUNT_ANGLES = ("beta", "gamma", "psi", "epsilon", "pitch", "roll")

#: Named outputs and their units.
OUTPUTS = {
    "lidar_speed": "m/s", "lidar_direction": "deg", "lidar_u": "m/s", "lidar_v": "m/s",
    "lidar_w": "m/s", "lidar_velocity": "m/s", "point_speed": "m/s", "point_direction": "deg",
    "cff_u": "1", "cff_v": "1", "cff_w": "1", "cff_U": "1", "cff_th": "deg",
    "cfp_u": "1", "cfp_v": "1", "cfp_w": "1", "cfp_U": "1", "cfp_th": "deg",
    "los": "m/s", "inv_speed": "m/s", "inv_direction": "deg",
}
#: Outputs that are angles: Monte Carlo and finite-difference deviations are wrapped.
ANGLE_OUTPUTS = ("lidar_direction", "point_direction", "cff_th", "cfp_th", "inv_direction")
_INVERSE_OUTPUTS = ("inv_speed", "inv_direction")
_SCENE_PATH = re.compile(r"^scene\.([A-Za-z_]\w*)(?:\[([0-9,\s]+)\])?$")


# ------------------------------------------------------------------------------------------
# Names


def _expand(names: Sequence[str], fname: str) -> tuple[str, ...]:
    out: list[str] = []
    for name in names:
        if not isinstance(name, str):
            raise ValueError(f"{fname}: input names must be strings, got {name!r}.")
        parts = _ALIASES.get(name, (name,))
        for p in parts:
            if p not in INPUTS and not _SCENE_PATH.match(p):
                raise ValueError(
                    f"{fname}: unknown input {p!r}; choose from {sorted(INPUTS) + ['location']} "
                    f"or a scene parameter path like 'scene.radius'."
                )
            if p in out:
                raise ValueError(f"{fname}: input {p!r} is named twice.")
            out.append(p)
    if not out:
        raise ValueError(f"{fname}: no inputs named.")
    return tuple(out)


def _scene_leaf(field, name: str):
    """The attribute and index tuple of a ``scene.NAME[i, j]`` path (validated)."""
    m = _SCENE_PATH.match(name)
    attr = m.group(1)
    idx = () if m.group(2) is None else tuple(int(i) for i in m.group(2).split(","))
    return attr, idx


def _check_scene_path(field, name: str, stacked: bool, fname: str) -> None:
    attr, idx = _scene_leaf(field, name)
    value = getattr(field, attr, None)
    if isinstance(field, GridField) or attr in ("origin", "origin_lo"):
        raise ValueError(
            f"{fname}: {name!r}: only an analytic scene's own parameters can be named (not a "
            f"GridField's arrays, nor the origin); scale the flow with 'speed'."
        )
    if not isinstance(value, jax.Array) or not jnp.issubdtype(value.dtype, jnp.floating):
        params = [k for k, v in vars(field).items()
                  if isinstance(v, jax.Array) and k not in ("origin", "origin_lo")]
        raise ValueError(
            f"{fname}: {type(field).__name__} has no float parameter {attr!r} for {name!r}; "
            f"it has {params}."
        )
    shape = value.shape[1:] if stacked else value.shape
    if len(idx) != len(shape) or any(not 0 <= i < n for i, n in zip(idx, shape, strict=False)):
        raise ValueError(
            f"{fname}: {name!r} must index the {shape}-shaped parameter {attr!r} with "
            f"{len(shape)} indices in range (e.g. 'scene.{attr}"
            + ("[" + ",".join("0" * len(shape)) + "]'" if shape else "'") + ")."
        )


def _speed_attr(field) -> str | None:
    for attr in ("speed", "speed_ref"):
        v = getattr(field, attr, None)
        if isinstance(v, jax.Array):
            return attr
    return None


def _has_direction(field) -> bool:
    return isinstance(getattr(field, "direction", None), jax.Array)


def _infers_uref(field) -> bool:
    return isinstance(getattr(field, "speed", None), jax.Array) and _has_direction(field)


def _units(name: str) -> str:
    return INPUTS.get(name, "unit")


# ------------------------------------------------------------------------------------------
# The perturbed forward model


class _Scaled(AbstractField):
    """A field whose velocities are multiplied by `factor` (the free stream scaled)."""

    origin: Float[Array, 3]
    origin_lo: Float[Array, 3]
    inner: AbstractField
    factor: Float[Array, ""]

    @property
    def resolution(self) -> float | None:
        return self.inner.resolution

    def sample_local(self, points):
        return self.factor * self.inner.sample_local(points)

    def los_local(self, points, directions):
        return self.factor * self.inner.los_local(points, directions)


def _perturb(field, scan, mount, heights, u_ref, names, delta, infer):
    """Apply the perturbations `delta` ``(p,)`` (units of `names`) to the configuration."""
    d = dict(zip(names, [delta[i] for i in range(len(names))], strict=True))
    if any(k in d for k in ("x", "y", "z")):
        shift = jnp.stack([d.get(k, jnp.zeros((), delta.dtype)) for k in ("x", "y", "z")])
        mount = eqx.tree_at(lambda m: m.location, mount, mount.location + shift.astype(
            mount.location.dtype))
    for a in _MOUNT_ANGLES:
        if a in d:
            mount = eqx.tree_at(lambda m, a=a: getattr(m, a), mount, getattr(mount, a) + d[a])
    if "cone_angle" in d:
        scan = eqx.tree_at(lambda s: s.cone_angle, scan, scan.cone_angle + d["cone_angle"])
    if "heights" in d:
        heights = heights + d["heights"]
    for k, v in d.items():
        if k.startswith("scene."):
            attr, idx = _scene_leaf(field, k)
            leaf = getattr(field, attr)
            field = eqx.tree_at(lambda f, attr=attr: getattr(f, attr), field,
                                leaf.at[idx].add(v.astype(leaf.dtype)))
    if u_ref is None and infer:  # the scene's own free stream
        speed_attr = _speed_attr(field)
        if "speed" in d:
            field = eqx.tree_at(lambda f: getattr(f, speed_attr), field,
                                getattr(field, speed_attr) + d["speed"])
        if "direction" in d:
            field = eqx.tree_at(lambda f: f.direction, field, field.direction + d["direction"])
        u_ref = field.speed * heading(field.direction, field.dtype)
    elif u_ref is not None and ("speed" in d or "direction" in d):
        u_ref = jnp.asarray(u_ref)
        speed0 = horizontal_speed(u_ref)
        dir0 = wind_direction(u_ref)
        speed = speed0 + d.get("speed", 0.0)
        direction = dir0 + d.get("direction", 0.0)
        u_ref = speed * heading(direction, u_ref.dtype) + jnp.stack(
            [0.0, 0.0, 1.0]).astype(u_ref.dtype) * u_ref[2]
        if "speed" in d:
            attr = _speed_attr(field)
            if attr is not None:  # the scene's own speed, scaled with the free stream
                field = eqx.tree_at(lambda f: getattr(f, attr), field,
                                    getattr(field, attr) * (speed / speed0))
            else:
                field = _Scaled(field.origin, field.origin_lo, field, speed / speed0)
        if "direction" in d:
            field = eqx.tree_at(lambda f: f.direction, field, field.direction + d["direction"])
    return field, scan, mount, heights, u_ref


def _outputs_of(sim, outputs):
    out = {}
    for name in outputs:
        if name == "lidar_speed":
            v = sim.lidar_speed
        elif name == "lidar_direction":
            v = sim.lidar_direction
        elif name in ("lidar_u", "lidar_v", "lidar_w"):
            v = sim.lidar_velocity[:, "uvw".index(name[-1])]
        elif name == "point_speed":
            v = sim.point_speed
        elif name == "point_direction":
            v = sim.point_direction
        else:
            v = getattr(sim, name)
        out[name] = v
    return out


def _one(field, scan, mount, heights, u_ref, probe, delta, cfg):
    names, outputs, infer, point_reference, ratio_tol = cfg
    f, s, m, h, u = _perturb(field, scan, mount, heights, u_ref, names, delta, infer)
    sim = _simulate(f, s, m, h, u, probe, ratio_tol, point_reference=point_reference)
    return _outputs_of(sim, outputs)


def _jacobian_one(field, scan, mount, heights, u_ref, probe, cfg, hessian=False):
    dtype = field.dtype
    delta0 = jnp.zeros((len(cfg[0]),), dtype)

    def f(delta):
        out = _one(field, scan, mount, heights, u_ref, probe, delta, cfg)
        return out, out

    if not hessian:
        jac, value = jax.jacfwd(f, has_aux=True)(delta0)
        return value, jac

    def g(delta):  # forward over forward: the p x p second derivatives
        j, v = jax.jacfwd(f, has_aux=True)(delta)
        return j, (j, v)

    hess, (jac, value) = jax.jacfwd(g, has_aux=True)(delta0)
    return value, jac, hess


def _map_sectors(fn, field, mount, u_ref, axes):
    """vmap `fn(field, mount, u_ref)` over the sectors (`axes` = (field, mount, u_ref) axes)."""
    field_axis, mount_axis, uref_axis = axes
    if field_axis is None and mount_axis is None and uref_axis is None:
        return fn(field, mount, u_ref)
    grid = isinstance(field, GridField) and field_axis == 0

    def one(field_leaf, m, u):
        f = unstack_field(field, field_leaf) if grid else field_leaf
        return fn(f, m, u)

    batched = field.velocity if grid else field
    return jax.vmap(one, in_axes=(field_axis, mount_axis, uref_axis))(batched, mount, u_ref)


@eqx.filter_jit
def _jacobian_batch(field, scan, mount, heights, u_ref, probe, cfg, axes):
    return _map_sectors(
        lambda f, m, u: _jacobian_one(f, scan, m, heights, u, probe, cfg), field, mount, u_ref,
        axes)


# ------------------------------------------------------------------------------------------
# Preparation shared by `sensitivity` and `uncertainty`


def _prepare(fname, field, scan, mount, heights, u_ref, probe, names, outputs, inverse=False):
    field, mount, u_ref, heights, probe, axes, given = rotation_arguments(
        fname, field, scan, mount, heights, u_ref, probe, names=("mount", "u_ref"))
    field_axis, mount_axis, uref_axis = axes
    n_sectors = next(iter(given.values())) if given else None
    first_field = unstack_field(field, 0) if field_axis == 0 else field
    first_mount = mount if mount_axis is None else mount[0]
    heights = heights.astype(first_field.dtype)

    # names and outputs
    infer = u_ref is None and _infers_uref(first_field)
    for n in names:
        if n in ("pitch", "roll") and not hasattr(first_mount, n):
            raise ValueError(f"{fname}: this lidarjax's Mount has no {n!r} (tilt).")
        if n.startswith("scene."):
            _check_scene_path(first_field, n, False, fname)
        if n == "speed" and u_ref is None and not infer:
            raise ValueError(
                f"{fname}: input 'speed' needs `u_ref` (the free stream) or a scene with its "
                f"own `speed` and `direction`.")
        if n == "direction":
            if not _has_direction(first_field):
                raise ValueError(
                    f"{fname}: input 'direction' turns the free stream, but a "
                    f"{type(first_field).__name__}'s inflow is fixed (for a GridField, by its "
                    f"CFD run): rotate the platform with 'beta' instead, or use a scene with "
                    f"its own `direction`.")
            if u_ref is None and not infer:
                raise ValueError(f"{fname}: input 'direction' needs `u_ref` (the free stream).")
    if isinstance(outputs, str):
        outputs = (outputs,)
    outputs = tuple(outputs)
    if not outputs:
        raise ValueError(f"{fname}: no outputs named.")
    for o in outputs:
        if o not in OUTPUTS:
            raise ValueError(f"{fname}: unknown output {o!r}; choose from {sorted(OUTPUTS)}.")
        if o in _INVERSE_OUTPUTS and not inverse:
            raise ValueError(
                f"{fname}: output {o!r} needs a response table: "
                f"lidarjax.uncertainty(..., table=table).")
        if o.startswith("cff_") and u_ref is None and not infer:
            raise ValueError(
                f"{fname}: output {o!r} needs `u_ref` (the free stream, CFD frame, m/s) or a "
                f"scene with its own `speed` and `direction`.")
    if len(set(outputs)) != len(outputs):
        raise ValueError(f"{fname}: an output is named twice in {outputs}.")
    point_reference = any(o.startswith(("cfp_", "point_")) for o in outputs)
    return (field, scan, mount, heights, u_ref, probe, infer, point_reference,
            (field_axis, mount_axis, uref_axis), n_sectors)


def _default_outputs(field, u_ref):
    f = field if isinstance(field, AbstractField) else list(field)[0]
    if isinstance(f, AbstractField) and _is_stacked(f):
        f = unstack_field(f, 0)
    if u_ref is not None or _infers_uref(f):
        return ("lidar_speed", "lidar_direction", "cff_U", "cff_th")
    return ("lidar_speed", "lidar_direction")


# ------------------------------------------------------------------------------------------
# Results


def _unit_of(output: str, inp: str) -> str:
    return f"{OUTPUTS[output]} per {_units(inp)}"


def _fmt(v: float) -> str:
    return "nan" if not np.isfinite(v) else f"{v: .3e}"


class Sensitivity(eqx.Module):
    """Results of `sensitivity`.

    - `inputs`: the inputs' names (``location`` expanded to ``x, y, z``); `input_units`.
    - `outputs`: the outputs' names; `output_units`.
    - `heights`: ``(h,)`` m.
    - `value[out]`: the nominal output, ``(..., h)`` (``los`` ``(..., h, b)``,
      ``lidar_velocity`` ``(..., h, 3)``); ``...`` is the sector axis of a batch.
    - `jacobian[out]`: ``value[out].shape + (p,)``: d out / d input in ``unit(out) per
      unit(input)`` (`units`).
    """

    inputs: tuple[str, ...] = eqx.field(static=True)
    outputs: tuple[str, ...] = eqx.field(static=True)
    heights: Float[Array, " h"]
    value: dict
    jacobian: dict

    @property
    def input_units(self) -> tuple[str, ...]:
        return tuple(_units(n) for n in self.inputs)

    @property
    def output_units(self) -> tuple[str, ...]:
        return tuple(OUTPUTS[o] for o in self.outputs)

    def units(self, output: str, inp: str) -> str:
        """Unit of ``jacobian[output][..., inputs.index(inp)]``, e.g. ``'m/s per deg'``."""
        return _unit_of(output, inp)

    def table(self, output: str | None = None, sector: int | None = None) -> str:
        """A text table per height of d `output` / d input (default: every per-height
        output), for one `sector` of a batch (default 0)."""
        outs = [output] if output is not None else [
            o for o in self.outputs if o not in ("los", "lidar_velocity")]
        lines = []
        for o in outs:
            j = np.asarray(self.jacobian[o])
            v = np.asarray(self.value[o])
            if j.ndim == 3:
                j, v = j[sector or 0], v[sector or 0]
            if j.ndim != 2:
                raise ValueError(f"Sensitivity.table: {o!r} is not per height; read .jacobian.")
            lines.append(f"d {o} / d input  ({OUTPUTS[o]} per input unit)")
            lines.append(f"{'h (m)':>8s} {o:>12s} " + " ".join(
                f"{n + ' [' + _units(n) + ']':>14s}" for n in self.inputs))
            for k, h in enumerate(np.asarray(self.heights)):
                lines.append(f"{h:8.2f} {v[k]:12.4f} " + " ".join(
                    f"{_fmt(x):>14s}" for x in j[k]))
            lines.append("")
        return "\n".join(lines).rstrip()


def sensitivity(
    field: AbstractField | Sequence[AbstractField],
    scan: Scan,
    mount: Mount | Sequence[Mount],
    heights: Float[ArrayLike, " h"],
    *,
    u_ref: Float[ArrayLike, 3] | Float[ArrayLike, "s 3"] | None = None,
    probe: AbstractProbe | None = None,
    wrt: Sequence[str] = ("location", "beta", "gamma", "epsilon", "pitch", "roll",
                          "cone_angle", "heights"),
    outputs: Sequence[str] | None = None,
    ratio_tol: float = DEFAULT_RATIO_TOL,
) -> Sensitivity:
    """Jacobians of lidar outputs with respect to installation, free-stream and scene inputs.

    **Arguments:**

    - `field`, `scan`, `mount`, `heights`, `u_ref`, `probe`, `ratio_tol`: as for
      `lidarjax.simulate`; `field` may also be a list or stack of one per sector, `mount` a
      batched `Mount` or a list, and `u_ref` ``(s, 3)``, as for
      `lidarjax.simulate_rotations`. Without `u_ref`, a scene with its own ``speed`` and
      ``direction`` (uniform, hemisphere, hill) supplies its free stream
      ``speed * heading(direction)``.
    - `wrt`: input names (module docs): ``location`` (= ``x, y, z``), ``beta``, ``gamma``,
      ``psi``, ``epsilon``, ``pitch``, ``roll``, ``cone_angle``, ``heights``, ``speed``,
      ``direction``, ``scene.NAME[...]``.
    - `outputs`: output names (module docs); default lidar speed and direction, plus
      ``cff_U`` and ``cff_th`` when there is a free stream.

    **Returns:** a `Sensitivity` with ``jacobian[out]`` shaped ``value[out].shape + (p,)`` in
    ``unit(out) per unit(input)`` (degrees for angles, metres, m/s), a sector axis first for
    a batch. One compiled forward-mode call (`jax.jacfwd` over the ``p`` inputs) per
    configuration (names, shapes, scan method and probe are static; numbers never
    recompile).

    Raises `ValueError` before compiling for unknown names, inputs the configuration cannot
    perturb (e.g. ``direction`` of a `GridField`) and the errors of `simulate`.
    """
    names = _expand(wrt, "sensitivity")
    if outputs is None:
        outputs = _default_outputs(field, u_ref)
    (field, scan, mount, heights, u_ref, probe, infer, point_reference, axes,
     _) = _prepare("sensitivity", field, scan, mount, heights, u_ref, probe, names, outputs)
    outputs = tuple([outputs] if isinstance(outputs, str) else outputs)
    cfg = (names, outputs, infer, point_reference, float(ratio_tol))
    value, jac = _jacobian_batch(field, scan, mount, heights, u_ref, probe, cfg, axes)
    return Sensitivity(names, outputs, heights, value, jac)


# ------------------------------------------------------------------------------------------
# Uncertainty


class Budget(eqx.Module):
    """Results of `uncertainty`: per-height uncertainty budgets (GUM) of each output.

    - `inputs`, `outputs`, `heights`, `value`, `jacobian`: as in `Sensitivity`; with a
      table, `inputs` ends with ``los_noise`` (the record noise: independent, identically
      distributed LOS errors of each beam) whose column in ``jacobian[inv_*]`` is the
      root-sum-square over the beams of d out / d LOS_b (zero for the forward outputs).
    - `std_in`: ``(p,)`` the inputs' standard uncertainties; `correlation` ``(p, p)``.
    - `std[out]`: combined standard uncertainty ``sqrt(J C J^T)`` (plus the second-order
      term with ``second_order=True``), ``value[out].shape``; `std_linear[out]` the first-order
      part; `second_order[out]` the second-order part ``sqrt(tr((H C)^2) / 2)`` (empty dict
      without it).
    - `contribution[out]`: ``(..., p)`` each input's ``|dout/dx_i| u(x_i)`` (GUM's
      ``u_i(y)``), in the output's unit.
    - `share[out]`: ``(..., p)`` each input's part of the variance, ``J_i (C J^T)_i / u^2``
      (sums to 1; negative parts appear only with negative correlations).
    - `n_monte_carlo`; `mc_std[out]` the Monte Carlo standard deviation of the same function
      over ``n_monte_carlo`` samples of the inputs (angles: wrapped deviations from the
      nominal value; NaN samples ignored) and `mc_relative_difference[out]` ``mc_std / std -
      1`` (empty dicts without Monte Carlo).
    """

    inputs: tuple[str, ...] = eqx.field(static=True)
    outputs: tuple[str, ...] = eqx.field(static=True)
    heights: Float[Array, " h"]
    std_in: Float[Array, " p"]
    correlation: Float[Array, "p p"]
    value: dict
    jacobian: dict
    std: dict
    std_linear: dict
    second_order: dict
    contribution: dict
    share: dict
    n_monte_carlo: int = eqx.field(static=True)
    mc_std: dict
    mc_relative_difference: dict

    @property
    def input_units(self) -> tuple[str, ...]:
        return tuple(_units(n) if n != "los_noise" else "m/s" for n in self.inputs)

    def table(self, output: str | None = None, sector: int | None = None) -> str:
        """Text budget per height: nominal value, combined standard uncertainty, each
        input's contribution (and the Monte Carlo check), for one `sector` (default 0)."""
        outs = [output] if output is not None else [
            o for o in self.outputs if o not in ("los", "lidar_velocity")]
        lines = []
        for o in outs:
            arrays = [np.asarray(self.value[o]), np.asarray(self.std[o]),
                      np.asarray(self.contribution[o])]
            mc = np.asarray(self.mc_std[o]) if o in self.mc_std else None
            so = np.asarray(self.second_order[o]) if o in self.second_order else None
            if arrays[0].ndim == 2:
                arrays = [a[sector or 0] for a in arrays]
                mc = None if mc is None else mc[sector or 0]
                so = None if so is None else so[sector or 0]
            v, u, c = arrays
            if v.ndim != 1:
                raise ValueError(f"Budget.table: {o!r} is not per height; read .std.")
            unit = OUTPUTS[o]
            lines.append(f"{o} [{unit}]: standard uncertainty and contributions |c_i| u_i")
            head = f"{'h (m)':>8s} {'value':>10s} {'u':>10s} " + " ".join(
                f"{n:>10s}" for n in self.inputs)
            head += f" {'2nd order':>10s}" if so is not None else ""
            lines.append(head + (f" {'u (MC)':>10s} {'MC/u-1':>9s}" if mc is not None else ""))
            for k, h in enumerate(np.asarray(self.heights)):
                row = f"{h:8.2f} {v[k]:10.4f} {u[k]:10.3e} " + " ".join(
                    f"{x:10.3e}" for x in c[k])
                if so is not None:
                    row += f" {so[k]:10.3e}"
                if mc is not None:
                    row += f" {mc[k]:10.3e} {mc[k] / u[k] - 1:+9.2%}" if u[k] > 0 else ""
                lines.append(row)
            lines.append("")
        return "\n".join(lines).rstrip()


def _covariance(names, std, correlation, fname):
    """Standard uncertainties ``(p,)`` and correlation ``(p, p)`` in the order of `names`."""
    std_in = np.zeros(len(names))
    given = {}
    for key, value in std.items():
        parts = _ALIASES.get(key, (key,))
        vals = np.atleast_1d(np.asarray(value, dtype=np.float64))
        if vals.size not in (1, len(parts)):
            raise ValueError(f"{fname}: std[{key!r}] must be one value or {len(parts)}, got "
                             f"{value!r}.")
        vals = np.broadcast_to(vals, (len(parts),))
        for p, v in zip(parts, vals, strict=True):
            if not (np.isfinite(v) and v >= 0):
                raise ValueError(f"{fname}: std[{key!r}] must be finite and >= 0 (standard "
                                 f"uncertainty in {_units(p)}), got {value!r}.")
            given[p] = v
    for i, n in enumerate(names):
        std_in[i] = given[n]
    p = len(names)
    if correlation is None:
        corr = np.eye(p)
    elif isinstance(correlation, Mapping):
        corr = np.eye(p)
        for pair, rho in correlation.items():
            if not (isinstance(pair, tuple) and len(pair) == 2):
                raise ValueError(f"{fname}: correlation keys must be pairs of input names, "
                                 f"e.g. ('pitch', 'roll'); got {pair!r}.")
            for a in pair:
                if a not in names:
                    raise ValueError(f"{fname}: correlation names {a!r}, which has no std; "
                                     f"inputs are {list(names)}.")
            i, j = names.index(pair[0]), names.index(pair[1])
            if i == j or not (-1.0 <= float(rho) <= 1.0):
                raise ValueError(f"{fname}: correlation {pair}: {rho!r} must be in [-1, 1] "
                                 f"between two different inputs.")
            corr[i, j] = corr[j, i] = float(rho)
    else:
        corr = np.asarray(correlation, dtype=np.float64)
        if corr.shape != (p, p):
            raise ValueError(f"{fname}: correlation must be ({p}, {p}) in the order "
                             f"{list(names)}, got shape {corr.shape}.")
        if not np.allclose(corr, corr.T) or not np.allclose(np.diag(corr), 1.0):
            raise ValueError(f"{fname}: correlation must be symmetric with a unit diagonal.")
    if np.linalg.eigvalsh(corr).min() < -1e-10:
        raise ValueError(f"{fname}: correlation matrix is not positive semi-definite.")
    return std_in, corr


def _budget(jac, cov, std_in):
    """GUM: u^2 = J C J^T; contributions |J_i| u_i; variance shares J_i (C J^T)_i / u^2."""
    cj = jnp.einsum("ij,...j->...i", cov, jac, precision=HIGHEST)
    var = jnp.sum(jac * cj, axis=-1)
    u = jnp.sqrt(jnp.maximum(var, 0.0))
    share = jac * cj / jnp.where(var > 0, var, 1.0)[..., None]
    return u, jnp.abs(jac) * std_in, share


def _mc_stats(samples, nominal, name):
    """Standard deviation over the sample axis 0 (angles: of wrapped deviations), NaN-safe."""
    dev = samples - nominal
    if name in ANGLE_OUTPUTS:
        dev = wrap180(dev)
    ok = jnp.isfinite(dev)
    n = jnp.sum(ok, axis=0)
    mean = jnp.sum(jnp.where(ok, dev, 0), axis=0) / jnp.maximum(n, 1)
    var = jnp.sum(jnp.where(ok, (dev - mean) ** 2, 0), axis=0) / jnp.maximum(n - 1, 1)
    return jnp.where(n > 1, jnp.sqrt(var), jnp.nan)


def _inverse_fn(table):
    def inv(los):  # (..., h, b) -> dict of (..., h)
        r = invert(table, los, batch_size="all")
        return {"inv_speed": r.speed, "inv_direction": r.direction}

    return inv


def _with_inverse(table, value, jac, inv_outputs):
    """Add the inverse outputs to one sector's `value` and `jac` (in place): `invert` at the
    nominal LOS and its implicit gradients d(inverse)/d(LOS) chained with d(LOS)/d(inputs),
    plus one column for the record noise (the norm of the LOS gradient)."""
    inv = _inverse_fn(table)
    los = value["los"]
    # d(inverse)/d(LOS) at the nominal LOS: implicit gradients of `invert`, with its values
    # (one trace of the solver)
    def value_twice(x):  # the Jacobian's output and, as its aux, the value
        r = inv(x)
        return r, r

    g_all, inv_val = jax.jacfwd(value_twice, has_aux=True)(los)  # (h,)+(h, b)
    h_idx = jnp.arange(los.shape[0])
    j_los = jnp.where(jnp.isfinite(jac["los"]), jac["los"], 0.0)
    for o in inv_outputs:
        g = g_all[o][h_idx, h_idx]  # (h, b): each height depends on its own beams
        g = jnp.where(jnp.isfinite(g), g, 0.0)
        value[o] = inv_val[o]
        jac[o] = jnp.concatenate(
            [jnp.einsum("hb,hbp->hp", g, j_los, precision=HIGHEST),
             jnp.sqrt(jnp.sum(g * g, axis=-1))[:, None]], axis=-1)


def _monte_carlo(sample, value, k, chol, n_mc, chunk, p, fwd_outputs, inv_outputs, table,
                 noise, dtype):
    """Monte Carlo standard deviations of one sector: `n_mc` Gaussian draws of the inputs
    (Cholesky factor `chol`) through `sample` (in chunks of `chunk`), and for the inverse
    outputs the drawn LOS plus i.i.d. record noise through `invert`."""
    mc = {}
    k1, k2 = jax.random.split(k)
    z = jax.random.normal(k1, (n_mc, p), dtype)
    deltas = jnp.matmul(z, chol.T.astype(dtype), precision=HIGHEST)
    draws = map_in_batches(sample, deltas, chunk)
    for o in fwd_outputs:
        mc[o] = _mc_stats(draws[o], value[o], o)
    if inv_outputs:
        los_s = draws["los"] + noise * jax.random.normal(k2, draws["los"].shape, dtype)
        inv_s = _inverse_fn(table)(los_s)
        for o in inv_outputs:
            mc[o] = _mc_stats(inv_s[o], value[o], o)
    return mc


def _over_sectors(per_sector, field, mount, u_ref, key, axes):
    """`per_sector` of a single configuration, or vmapped over the sectors' axes `axes`
    (field, mount, u_ref) with one random key per sector."""
    field_axis, mount_axis, uref_axis = axes
    if field_axis is None and mount_axis is None and uref_axis is None:
        return per_sector(field, mount, u_ref, key)
    n = _sector_count(field, mount, u_ref, axes)
    keys = jax.random.split(key, n)
    grid = isinstance(field, GridField) and field_axis == 0

    def one(field_leaf, m, u, k):
        f = unstack_field(field, field_leaf) if grid else field_leaf
        return per_sector(f, m, u, k)

    batched = field.velocity if grid else field
    return jax.vmap(one, in_axes=(field_axis, mount_axis, uref_axis, 0))(
        batched, mount, u_ref, keys)


def _gum(outputs, jac, cov, std_in, noise, need_los, p, dtype):
    """Every output's GUM budget (`_budget`): with the inverse outputs the record noise is
    one more input (the LOS error of every beam, i.i.d.), which the forward outputs do not
    see (their Jacobians get a zero column, in place in `jac`)."""
    cov = cov.astype(dtype)
    std_in = std_in.astype(dtype)
    if need_los:
        cov = jnp.zeros((p + 1, p + 1), dtype).at[:p, :p].set(cov).at[p, p].set(noise**2)
        std_in = jnp.concatenate([std_in, noise[None]])
    std, contribution, share = {}, {}, {}
    for o in outputs:
        j = jac[o]
        if need_los and o not in _INVERSE_OUTPUTS:
            j = jnp.concatenate([j, jnp.zeros(j.shape[:-1] + (1,), j.dtype)], axis=-1)
        jac[o] = j
        std[o], contribution[o], share[o] = _budget(j, cov, std_in)
    return std, contribution, share, cov


def _second_order_std(hess, cov, p, fwd_outputs):
    """Gaussian inputs: the second-order term of var(J d + d^T H d / 2) = J C J^T +
    tr((H C)^2) / 2, as a standard deviation per forward output."""
    second = {}
    c = cov[:p, :p]
    for o in fwd_outputs:
        hc = jnp.einsum("...ij,jk->...ik", jnp.where(jnp.isfinite(hess[o]), hess[o], 0.0), c,
                        precision=HIGHEST)
        var2 = 0.5 * jnp.einsum("...ij,...ji->...", hc, hc, precision=HIGHEST)
        second[o] = jnp.sqrt(jnp.maximum(var2, 0.0))
    return second


@eqx.filter_jit
def _uncertainty_core(field, scan, mount, heights, u_ref, probe, cfg, axes, chol, std_in,
                      cov, key, table, noise, n_mc, chunk):
    names, outputs, infer, point_reference, ratio_tol, second_order = cfg
    fwd_outputs = tuple(o for o in outputs if o not in _INVERSE_OUTPUTS)
    inv_outputs = tuple(o for o in outputs if o in _INVERSE_OUTPUTS)
    need_los = bool(inv_outputs)
    run_outputs = fwd_outputs + (("los",) if need_los and "los" not in fwd_outputs else ())
    fcfg = (names, run_outputs, infer, point_reference, ratio_tol)
    dtype = field.dtype
    p = len(names)

    def per_sector(f, m, u, k):
        if second_order:
            value, jac, hess = _jacobian_one(f, scan, m, heights, u, probe, fcfg, True)
            value["_hess"] = hess
        else:
            value, jac = _jacobian_one(f, scan, m, heights, u, probe, fcfg)
        if need_los:
            _with_inverse(table, value, jac, inv_outputs)
        mc = {}
        if n_mc > 0:
            def sample(delta):
                return _one(f, scan, m, heights, u, probe, delta, fcfg)

            mc = _monte_carlo(sample, value, k, chol, n_mc, chunk, p, fwd_outputs,
                              inv_outputs, table, noise, dtype)
        return value, jac, mc

    value, jac, mc = _over_sectors(per_sector, field, mount, u_ref, key, axes)
    hess = value.pop("_hess", None)
    if need_los and "los" not in outputs:
        value.pop("los")
        jac.pop("los")
    std, contribution, share, cov = _gum(outputs, jac, cov, std_in, noise, need_los, p, dtype)
    second = {} if hess is None else _second_order_std(hess, cov, p, fwd_outputs)
    return value, jac, std, contribution, share, mc, second


def _sector_count(field, mount, u_ref, axes):
    field_axis, mount_axis, uref_axis = axes
    if field_axis == 0:
        return _n_stacked(field)
    if mount_axis == 0:
        return mount.batch_shape[0]
    return u_ref.shape[0]


def uncertainty(
    field: AbstractField | Sequence[AbstractField],
    scan: Scan,
    mount: Mount | Sequence[Mount],
    heights: Float[ArrayLike, " h"],
    *,
    std: Mapping[str, float | Sequence[float]],
    correlation: Mapping[tuple[str, str], float] | ArrayLike | None = None,
    u_ref: Float[ArrayLike, 3] | Float[ArrayLike, "s 3"] | None = None,
    probe: AbstractProbe | None = None,
    outputs: Sequence[str] | None = None,
    table=None,
    noise: float = 0.0,
    n_monte_carlo: int = 0,
    key: jax.Array | int | None = None,
    mc_batch_size: int | None = None,
    second_order: bool = False,
    ratio_tol: float = DEFAULT_RATIO_TOL,
) -> Budget:
    """Per-height uncertainty budgets of lidar outputs (GUM), optionally checked by Monte Carlo.

    **Arguments:**

    - `field`, `scan`, `mount`, `heights`, `u_ref`, `probe`, `ratio_tol`: as for
      `sensitivity` (single configurations or batches of sectors).
    - `std`: ``{input name: standard uncertainty}`` in the input's unit (module docs), e.g.
      ``{"epsilon": 0.5, "pitch": 0.2, "roll": 0.2, "location": 0.05}`` (``location`` takes
      one value for x, y, z or three). Only these inputs enter the budget.
    - `correlation`: None (independent inputs), ``{("pitch", "roll"): rho, ...}``, or a
      ``(p, p)`` matrix in the order of `Budget.inputs` (``location`` expanded).
    - `outputs`: output names (default: lidar speed and direction, ``cff_U`` and ``cff_th``
      with a free stream, and ``inv_speed``, ``inv_direction`` with a `table`).
    - `table`: a `lidarjax.ResponseTable` built for the *nominal* configuration (same scan,
      heights and beams). Then the inverse outputs ``inv_speed`` and ``inv_direction`` are the
      free stream `lidarjax.invert` recovers from the LOS the lidar would measure, and their
      budgets include the installation errors *and* the record noise (below).
    - `noise`: the record noise, the standard deviation of each beam's LOS, m/s (independent
      between beams; it enters the inverse outputs).
    - `n_monte_carlo`: with ``n > 0``, the same forward function (and inverse) is evaluated for
      `n` samples of the inputs drawn from ``N(nominal, C)`` (plus LOS noise for the
      inverse), vmapped in chunks of `mc_batch_size` samples (None: chosen per backend,
      256 on a CPU, all at once on a GPU when they fit in memory), and `Budget.mc_std` and
      `Budget.mc_relative_difference` report how far the linear propagation is off. The
      relative standard error of a Monte Carlo standard deviation is about
      ``1 / sqrt(2 (n - 1))``: 1 % needs about 5000 samples.
    - `key`: a `jax.random` key or integer seed for the Monte Carlo (default 0).
    - `second_order`: also propagate the second derivatives (forward over forward, ``p^2``
      directions): for Gaussian inputs the variance of ``J d + d^T H d / 2`` is
      ``J C J^T + tr((H C)^2) / 2``. Needed where an output is stationary in an input (a
      level lidar's speed in its tilt: the cosine error) and the first-order budget is
      small; `Budget.std` then includes the term (`Budget.second_order`), `Budget.std_linear`
      is the first-order one. Forward outputs only (the inverse outputs stay first order).

    **Method.** The Jacobian ``J = d out / d x`` (`sensitivity`, forward mode) and the
    covariance ``C = diag(u) R diag(u)`` of the inputs give the combined standard
    uncertainty ``u(out) = sqrt(J C J^T)`` per height (GUM, JCGM 100 section 5), each input's
    contribution ``|J_i| u_i`` and variance share. For the inverse, the table holds the
    response of the *nominal* installation, while the records come from the *true* one; to
    first order the corrected free stream ``theta = (U, d)`` then moves by
    ``G (dLOS/dx) dx + G e`` where ``dLOS/dx`` is the forward Jacobian of the LOS with respect
    to the installation (at the configuration's free stream), ``e`` the record noise and
    ``G = d theta / d LOS`` the implicit gradient of `lidarjax.invert` at the nominal LOS
    (optimistix's implicit adjoint: no differentiation through the solver's iterations). So
    ``u^2(theta) = G (J_LOS C J_LOS^T + sigma^2 I) G^T``; the noise appears in the budget as
    the input ``los_noise`` (std `noise`). An installation error the table would itself see
    (a tilt present in every CFD run) cancels; this budget is for errors the table does not
    know.

    **Returns:** a `Budget` (shapes as in `Sensitivity`; a sector axis first for a batch).
    One compiled call per configuration. Raises `ValueError` before compiling for unknown
    names, negative or non-finite standard uncertainties, a bad correlation matrix, a table
    whose heights and beams do not match, and the errors of `sensitivity`.
    """
    fname = "uncertainty"
    if not isinstance(std, Mapping) or not std:
        raise ValueError(f"{fname}: `std` must be a non-empty dict {{input name: standard "
                         f"uncertainty}}, e.g. {{'epsilon': 0.5, 'location': 0.05}}.")
    names = _expand(list(std), fname)
    std_in, corr = _covariance(names, std, correlation, fname)
    if table is not None:
        if not isinstance(table, ResponseTable):
            raise ValueError(f"{fname}: `table` must be a lidarjax.ResponseTable.")
    if outputs is None:
        outputs = _default_outputs(field, u_ref) + (_INVERSE_OUTPUTS if table is not None else ())
    outputs = tuple([outputs] if isinstance(outputs, str) else outputs)
    (field, scan, mount, heights, u_ref, probe, infer, point_reference, axes,
     n_sectors) = _prepare(fname, field, scan, mount, heights, u_ref, probe, names, outputs,
                           inverse=table is not None)
    inverse = any(o in _INVERSE_OUTPUTS for o in outputs)
    if second_order and inverse:
        raise ValueError(f"{fname}: second_order=True is for the forward outputs; leave the "
                         f"inverse outputs (inv_speed, inv_direction) out or use first order.")
    if table is not None:
        want = (heights.shape[0], scan.n_beams)
        if (table.n_heights, table.n_beams) != want:
            raise ValueError(f"{fname}: the table has (heights, beams) = "
                             f"{(table.n_heights, table.n_beams)}, the configuration {want}.")
    noise_f = float(noise)
    if not (np.isfinite(noise_f) and noise_f >= 0):
        raise ValueError(f"{fname}: `noise` must be >= 0 m/s, got {noise!r}.")
    n_mc = int(n_monte_carlo)
    if n_mc < 0 or n_mc == 1:
        raise ValueError(f"{fname}: `n_monte_carlo` must be 0 or at least 2, got {n_monte_carlo}.")
    if mc_batch_size is None:
        # a generous estimate of one sample's forward run, over all sectors at once
        per_sample = (np.dtype(heights.dtype).itemsize * (n_sectors or 1) * heights.shape[0]
                      * scan.n_beams * int(getattr(probe, "n_nodes", 1)) * 256)
        mc_batch_size = default_batch("monte_carlo", per_sample, max(n_mc, 1))
    else:
        mc_batch_size = positive_size(mc_batch_size, fname, "mc_batch_size")
    if key is None:
        key = jax.random.PRNGKey(0)
    elif isinstance(key, int | np.integer):
        key = jax.random.PRNGKey(int(key))
    dtype = heights.dtype
    cov = np.outer(std_in, std_in) * corr
    # a symmetric square root (works for semi-definite C: zero std or rho = +-1)
    w, v = np.linalg.eigh(cov)
    chol = (v * np.sqrt(np.clip(w, 0.0, None))) @ v.T
    cfg = (names, outputs, infer, point_reference, float(ratio_tol), bool(second_order))
    value, jac, std_lin, contribution, share, mc, second = _uncertainty_core(
        field, scan, mount, heights, u_ref, probe, cfg, axes, jnp.asarray(chol, dtype),
        jnp.asarray(std_in, dtype), jnp.asarray(cov, dtype), key, table,
        jnp.asarray(noise_f, dtype), n_mc, min(int(mc_batch_size), max(n_mc, 1)))
    inputs = names + (("los_noise",) if inverse else ())
    std_vec = np.concatenate([std_in, [noise_f]]) if inverse else std_in
    corr_full = np.eye(len(inputs))
    corr_full[: len(names), : len(names)] = corr
    std_out = {o: jnp.sqrt(std_lin[o] ** 2 + second[o] ** 2) if o in second else std_lin[o]
               for o in outputs}
    rel = {o: mc[o] / std_out[o] - 1.0 for o in mc}
    return Budget(inputs, outputs, heights, jnp.asarray(std_vec, dtype),
                  jnp.asarray(corr_full, dtype), value, jac, std_out, std_lin, second,
                  contribution, share, n_mc, mc, rel)


# ------------------------------------------------------------------------------------------
# Tables of results (for CSV writers)


def budget_columns(budget: Budget, output: str, sectors: Sequence[float] | None = None,
                   z_over_h: ArrayLike | None = None, sector_name: str = "beta"):
    """Columns and units of one per-height output of a `Budget`, one row per sector and
    height, for `lidarjax.io.write_table_csv`: the sector label (`sector_name`, e.g. the
    platform rotation in degrees), ``h``, optionally ``z/H``, the nominal value, the combined
    standard uncertainty ``u``, the Monte Carlo ``u_mc`` and ``mc_minus_lin`` (relative) when
    present, then per input its contribution ``u_<input>`` (output unit), variance share
    ``share_<input>`` and sensitivity coefficient ``d_<input>`` (output unit per input unit).

    **Returns:** ``(columns, units)`` dicts of 1-D float arrays and unit strings."""
    value = np.asarray(budget.value[output], dtype=np.float64)
    if value.ndim == 1:
        value = value[None]
        index = lambda a: np.asarray(a, np.float64)[None]  # noqa: E731
    elif value.ndim == 2:
        index = lambda a: np.asarray(a, np.float64)  # noqa: E731
    else:
        raise ValueError(f"budget_columns: {output!r} is not a per-height output.")
    s, h = value.shape
    labels = np.arange(s, dtype=np.float64) if sectors is None else np.asarray(sectors, float)
    unit = OUTPUTS[output]
    cols = {sector_name: np.repeat(labels, h), "h": np.tile(np.asarray(budget.heights), s)}
    units = {sector_name: "deg" if sector_name == "beta" else "1", "h": "m"}
    if z_over_h is not None:
        zh = np.broadcast_to(np.asarray(z_over_h, np.float64), (s, h))
        cols["z/H"] = zh.ravel()
        units["z/H"] = "1"
    cols[output] = value.ravel()
    units[output] = unit
    cols["u"] = index(budget.std[output]).ravel()
    units["u"] = unit
    if output in budget.second_order:
        cols["u_linear"] = index(budget.std_linear[output]).ravel()
        cols["u_second_order"] = index(budget.second_order[output]).ravel()
        units["u_linear"] = units["u_second_order"] = unit
    if output in budget.mc_std:
        cols["u_mc"] = index(budget.mc_std[output]).ravel()
        cols["mc_minus_lin"] = index(budget.mc_relative_difference[output]).ravel()
        units["u_mc"], units["mc_minus_lin"] = unit, "1"
    c = index(budget.contribution[output]).reshape(s * h, -1)
    sh = index(budget.share[output]).reshape(s * h, -1)
    j = index(budget.jacobian[output]).reshape(s * h, -1)
    for i, name in enumerate(budget.inputs):
        in_unit = budget.input_units[i]
        cols[f"u_{name}"], units[f"u_{name}"] = c[:, i], unit
        cols[f"share_{name}"], units[f"share_{name}"] = sh[:, i], "1"
        cols[f"d_{name}"], units[f"d_{name}"] = j[:, i], f"{unit} per {in_unit}"
    return cols, units
