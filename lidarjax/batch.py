"""Many scenes at once: stacked fields and `simulate_rotations`.

`lidarjax.simulate` is a pure jit-compiled function, so `jax.vmap` batches it over anything
numeric: inflow directions (fields), mounts, cone angles, heights, probe parameters. Only the
arrays that differ get a batch axis; everything else is shared:

```python
# one mount per sector, fields of one shape: stack the velocities only
stacked = lidarjax.stack_fields(fields)          # velocity (s, nx, ny, nz, 3), shared axes
def one(velocity, mount, u_ref):
    field = lidarjax.unstack_field(stacked, velocity)
    return lidarjax.simulate(field, scan, mount, heights, u_ref=u_ref)
sims = jax.vmap(one)(stacked.velocity, lidarjax.stack_mounts(mounts), u_refs)

# or, for that common case, the same in one call:
sims = lidarjax.simulate_rotations(fields, scan, mounts, heights, u_refs=u_refs)

# many platform rotations of one CFD run: one batched Mount, built from arrays
rotated = lidarjax.Mount(location, beta=jnp.linspace(0.0, 360.0, 10_000), psi=180.0)
sims = lidarjax.simulate_rotations(field, scan, rotated, heights)

# a cone-angle sweep in one field
sims = jax.vmap(lambda c: lidarjax.simulate(field, lidarjax.windcube_v1(c), mount, heights))(
    jnp.linspace(15.0, 35.0, 21))
```

Every result carries the batch axis first (``s`` for sectors). A `GridField` has the static
`uniform` flags and its axes; stacked fields must therefore share their axes (checked by
`stack_fields`) and only the velocity is batched. Analytic scenes of one type stack leaf by
leaf. The compiled graph does not depend on the batch size beyond shapes, and numbers never
recompile.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike, Float

from .corrections import DEFAULT_RATIO_TOL
from .field import AbstractField, GridField
from .forward import Simulation, _simulate, _validate, probe_for_field
from .mount import Mount
from .probe import AbstractProbe, PointProbe
from .scan import Scan

__all__ = ["stack_fields", "unstack_field", "stack_mounts", "unstack_mounts", "simulate_rotations"]


def stack_fields(fields: Sequence[AbstractField]) -> AbstractField:
    """Stack fields of one kind along a new leading axis ``s`` (a container for `jax.vmap`).

    - `GridField`\\ s must share their axes, origin and `uniform` flags exactly; the result
      is the first field with ``velocity`` of shape ``(s, nx, ny, nz, 3)`` (take one out
      with ``unstack_field(stacked, stacked.velocity[k])``). Do not sample the stacked field
      directly: it is a batch, not a field.
    - Analytic scenes of one type: every array leaf gets the leading axis.

    Raises `ValueError` for an empty list, mixed types or differing grids.
    """
    fields = list(fields)
    if not fields:
        raise ValueError("stack_fields: need at least one field.")
    kinds = {type(f) for f in fields}
    if len(kinds) != 1:
        raise ValueError(
            "stack_fields: fields must all be of one type, got "
            f"{sorted(k.__name__ for k in kinds)}."
        )
    first = fields[0]
    if isinstance(first, GridField):
        for k, f in enumerate(fields[1:], start=1):
            same = f.uniform == first.uniform and f.velocity.shape == first.velocity.shape
            for a, b in (
                (f.x_local, first.x_local), (f.y_local, first.y_local), (f.z_local, first.z_local),
                (f.origin, first.origin), (f.origin_lo, first.origin_lo),
                (f.index_scale, first.index_scale), (f.index_start, first.index_start),
            ):
                same = same and a.shape == b.shape and bool(jnp.array_equal(a, b))
            if not same:
                raise ValueError(
                    f"stack_fields: field {k} has other axes, origin or shape than field 0; "
                    f"stacked GridFields must share their grid (only velocities differ). "
                    f"Interpolate them onto one grid first."
                )
        if len({f.velocity.dtype for f in fields}) != 1:
            raise ValueError("stack_fields: velocities must share one dtype.")
        return eqx.tree_at(lambda g: g.velocity, first, jnp.stack([f.velocity for f in fields]))
    return jax.tree_util.tree_map(lambda *xs: jnp.stack(xs), *fields)


def unstack_field(stacked: AbstractField, velocity_or_index) -> AbstractField:
    """One field of a stack: for a stacked `GridField`, give its ``velocity[k]`` (inside
    `jax.vmap`, the mapped velocity) or the integer ``k``; for stacked scenes, the index."""
    if isinstance(stacked, GridField):
        v = velocity_or_index
        if isinstance(v, int | np.integer):
            v = stacked.velocity[v]
        return eqx.tree_at(lambda g: g.velocity, stacked, v)
    k = velocity_or_index
    return jax.tree_util.tree_map(lambda x: x[k], stacked)


def stack_mounts(mounts: Mount | Sequence[Mount]) -> Mount:
    """Stack mounts into one batched `Mount` (locations ``(s, 3)``, angles ``(s,)``).

    `mounts`: a list of single mounts, of batched mounts (their batches are concatenated) or
    of both; a batched `Mount` is returned as it is, a single one as a batch of one. Each
    field is stacked once on the host (linear in the number of mounts: about 0.5 s for 10,000
    single mounts on a 2-core CPU), or with `jax.numpy` when a leaf is traced. Dtypes promote as
    `jax.numpy.stack` would (float32 with float64 gives float64). Building the batch from
    arrays, ``Mount(locations, beta=betas, ...)``, is faster still.

    Raises `ValueError` for an empty list or an item that is not a `Mount`.
    """
    if isinstance(mounts, Mount):
        return mounts if mounts.batch_shape else jax.tree_util.tree_map(lambda x: x[None], mounts)
    mounts = list(mounts)
    if not mounts:
        raise ValueError("stack_mounts: need at least one mount.")
    for k, m in enumerate(mounts):
        if not isinstance(m, Mount):
            raise ValueError(
                f"stack_mounts: item {k} is a {type(m).__name__}, not a lidarjax.Mount."
            )
    names = [f.name for f in dataclasses.fields(Mount)]
    fields = [vars(m) for m in mounts]  # plain attribute reads: linear and fast
    single = all(f["location"].ndim == 1 for f in fields)
    traced = any(isinstance(x, jax.core.Tracer) for f in fields for x in f.values())
    out = []
    for name in names:
        column = [f[name] for f in fields]
        core = (3,) if name.startswith("location") else ()
        dtypes = {x.dtype for x in column}
        dtype = jnp.result_type(*dtypes)
        if traced:  # inside a transformation
            out.append(jnp.concatenate([jnp.reshape(x, (-1,) + core).astype(dtype)
                                        for x in column]))
        elif single and len(dtypes) == 1 and len(column) >= _DEVICE_STACK_MIN:
            out.append(_stack_on_device(column))
        else:
            host = [np.asarray(x).reshape((-1,) + core) for x in column]
            out.append(jnp.asarray(np.concatenate(host).astype(dtype, copy=False)))
    return jax.tree_util.tree_unflatten(jax.tree_util.tree_structure(mounts[0]), out)


#: Many single mounts are stacked on the device in compiled groups of this many leaves (one
#: compilation per leaf shape and dtype, about 2 microseconds a leaf), not copied to the host
#: one by one (about 5 microseconds a leaf, 10 under load).
_DEVICE_STACK_GROUP = 256
_DEVICE_STACK_MIN = 1024
_stack_group = jax.jit(lambda *xs: jnp.stack(xs))


def _stack_on_device(column):
    """``jnp.stack(column)`` for many equal-shaped concrete arrays, linear in their number:
    groups of `_DEVICE_STACK_GROUP` (the last padded with its last leaf) stacked by one
    compiled function, the groups joined on the host. Falls back to the host when the
    leaves live on different devices."""
    n, k = len(column), _DEVICE_STACK_GROUP
    padded = column + [column[-1]] * ((-n) % k)
    try:
        groups = [np.asarray(_stack_group(*padded[i:i + k])) for i in range(0, len(padded), k)]
    except ValueError:  # e.g. leaves committed to different devices
        groups = [np.stack([np.asarray(x) for x in column])]
    return jnp.asarray(np.concatenate(groups)[:n])


def unstack_mounts(mount: Mount | Sequence[Mount]) -> list[Mount]:
    """The single mounts of a batched `Mount` (``[mount[k] for k in range(s)]``); a single
    `Mount` gives ``[mount]`` and a list is returned as a list."""
    if isinstance(mount, Mount):
        return list(mount) if mount.batch_shape else [mount]
    return list(mount)


def _is_stacked(field: AbstractField) -> bool:
    """A stack from `stack_fields` (GridField: 5-D velocity; scenes: ``(s, 3)`` origin)."""
    if isinstance(field, GridField):
        return field.velocity.ndim == 5
    return field.origin.ndim == 2


def _n_stacked(stacked: AbstractField) -> int:
    if isinstance(stacked, GridField):
        return stacked.velocity.shape[0]
    return stacked.origin.shape[0]


def _sectors(field, scan, mount, heights, u_ref, probe, ratio_tol, *, point_reference,
             field_axis, mount_axis, uref_axis):
    grid = isinstance(field, GridField) and field_axis == 0

    def one(field_leaf, m, u):
        f = unstack_field(field, field_leaf) if grid else field_leaf
        return _simulate(f, scan, m, heights, u, probe, ratio_tol,
                         point_reference=point_reference)

    batched = field.velocity if grid else field
    return jax.vmap(one, in_axes=(field_axis, mount_axis, uref_axis))(batched, mount, u_ref)


_sectors_jit = jax.jit(
    _sectors, static_argnames=("point_reference", "field_axis", "mount_axis", "uref_axis")
)


def simulate_rotations(
    fields: AbstractField | Sequence[AbstractField],
    scan: Scan,
    mounts: Mount | Sequence[Mount],
    heights: Float[ArrayLike, " h"],
    *,
    u_refs: Float[ArrayLike, "s 3"] | Float[ArrayLike, 3] | None = None,
    probe: AbstractProbe | None = None,
    point_reference: bool = True,
    ratio_tol: float = DEFAULT_RATIO_TOL,
) -> Simulation:
    """`lidarjax.simulate` for every sector (inflow direction) at once, in one compiled call.

    **Arguments:**

    - `fields`: a list of fields of one kind and shape (one per sector), a stack from
      `stack_fields`, or one (unstacked) field shared by all sectors (then the sectors are
      the mounts, e.g. one CFD run seen by a rotated platform).
    - `scan`, `heights`, `probe`, `point_reference`, `ratio_tol`: shared, as in `simulate`.
    - `mounts`: one `Mount` for all sectors, a batched `Mount` (location ``(s, 3)`` and
      angles ``(s,)``, e.g. the same lidar with the platform rotation of each CFD run:
      ``Mount(location, beta=betas)``, built from arrays in one call), or a list of one
      `Mount` per sector (stacked with `stack_mounts`).
    - `u_refs`: free-stream vectors, ``(s, 3)`` one per sector or ``(3,)`` shared (CFD frame,
      m/s), or None.

    **Returns:** a `Simulation` whose every array has a leading sector axis ``s``
    (e.g. ``los`` is ``(s, h, b)``), equal to stacking `simulate` for each sector.
    """
    field, mount, u_refs, heights, probe, (field_axis, mount_axis, uref_axis), given = \
        rotation_arguments("simulate_rotations", fields, scan, mounts, heights, u_refs, probe)
    if not given:
        raise ValueError(
            "simulate_rotations: nothing to batch; give a list or stack of fields, of mounts or "
            "of u_refs (or call lidarjax.simulate)."
        )
    return _sectors_jit(
        field, scan, mount, heights, u_refs, probe, ratio_tol, point_reference=point_reference,
        field_axis=field_axis, mount_axis=mount_axis, uref_axis=uref_axis,
    )


def rotation_arguments(fname, fields, scan, mounts, heights, u_refs, probe, *,
                     names=("mounts", "u_refs")):
    """Normalise the sector arguments of `simulate_rotations` (and of `lidarjax.sensitivity`):
    stack field and mount lists, find which of fields, mounts and free streams carry the
    sector axis, check their counts agree, and validate one sector as `simulate` would,
    before compiling.

    **Returns:** ``(field, mount, u_refs, heights, probe, (field_axis, mount_axis,
    uref_axis), sizes)`` with each axis 0 or None and `sizes` the sector count of each
    batched argument (empty when nothing is batched). `names`: the caller's names of the
    mount and free-stream arguments, for the messages.
    """
    field = fields if isinstance(fields, AbstractField) else stack_fields(fields)
    field_axis = 0 if _is_stacked(field) else None
    if isinstance(mounts, Mount):
        mount = mounts
        mount_axis = 0 if mounts.batch_shape else None
    elif isinstance(mounts, Sequence) and not isinstance(mounts, str):
        if not all(isinstance(m, Mount) for m in mounts):
            raise ValueError(f"{fname}: `{names[0]}` must be a lidarjax.Mount (one, or a batch) "
                             f"or a list of Mounts.")
        mount = stack_mounts(mounts)
        mount_axis = 0
    else:
        raise ValueError(f"{fname}: `{names[0]}` must be a lidarjax.Mount (one, or a batch) or "
                         f"a list of Mounts.")
    u_refs = None if u_refs is None else jnp.asarray(u_refs)
    if u_refs is not None and (u_refs.shape[-1:] != (3,) or u_refs.ndim > 2):
        raise ValueError(f"{fname}: {names[1]} must be (s, 3) or (3,), got {u_refs.shape}.")
    uref_axis = 0 if u_refs is not None and u_refs.ndim == 2 else None
    sizes = {
        "fields": _n_stacked(field) if field_axis == 0 else None,
        "mounts": mount.batch_shape[0] if mount_axis == 0 else None,
        "u_refs": u_refs.shape[0] if uref_axis == 0 else None,
    }
    given = {k: v for k, v in sizes.items() if v is not None}
    if len(set(given.values())) > 1:
        raise ValueError(
            f"{fname}: sector counts differ ({given}); give one of each per sector "
            f"or a single shared one. E.g. {sizes['mounts']} mounts for "
            f"{sizes['fields']} sectors."
        )
    if probe is None:
        probe = PointProbe()
    first_field = unstack_field(field, 0) if field_axis == 0 else field
    first_mount = mount if mount_axis is None else mount[0]
    first_uref = None if u_refs is None else (u_refs if uref_axis is None else u_refs[0])
    _validate(first_field, scan, first_mount, heights, first_uref, probe)
    probe = probe_for_field(field, scan, heights, probe, mount=mount, caller=fname)
    heights = jnp.atleast_1d(jnp.asarray(heights))
    if not jnp.issubdtype(heights.dtype, jnp.floating):
        heights = heights.astype(first_field.dtype)
    return field, mount, u_refs, heights, probe, (field_axis, mount_axis, uref_axis), given
