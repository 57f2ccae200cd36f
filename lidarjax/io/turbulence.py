"""Turbulence boxes: Mann boxes in HAWC2 binary and TurbSim ``.bts`` full-field files.

Both readers return a `lidarjax.TurbulenceBox` (or, for TurbSim, a `TurbSimField`
that holds the full velocities and makes the box): fluctuations on a regular grid in the box
frame of `lidarjax.scenes.turbulence` (``x`` downwind, ``y`` to the left looking downwind,
``z`` up; node ``(i, j, k)`` at ``(i dx, (j - (ny-1)/2) dy, k dz)``), ready for
`lidarjax.scenes.FrozenTurbulence`.

**HAWC2 / Mann binary** (what the Mann generator, hipersim's ``to_hawc2`` and HAWC2 use):
three headerless files ``*u.bin``/``*v.bin``/``*w.bin`` (or ``*.turb``) of little-endian
float32, ``nx * ny * nz`` values each, ``z`` varying fastest, then ``y``, then ``x``
(C order of ``(nx, ny, nz)``); the box dimensions and spacings are not in the files and must
be given. ``u`` is the longitudinal fluctuation (positive downwind), ``v`` lateral (positive
to the left looking downwind, so that ``x, y, z`` is right-handed with ``z`` up), ``w``
vertical (positive up); the files hold fluctuations only (zero-mean). The box is the
*spatial* field of the Mann model with ``x`` downwind. HAWC2 and OpenFAST sweep it through the
turbine in increasing ``x`` (the first plane ``x = 0`` reaches the rotor first), which is the
mirror image of advecting the spatial field (Wise and Bachynski 2020); ``reverse_x=True``
reverses the ``x`` order so that lidarjax sees the planes in the order those codes do.

**TurbSim ``.bts``** (TurbSim user's guide, appendix on the binary full-field format):
a little-endian header ``int16 ID`` (7: ordinary, 8: periodic in time), ``int32 nz, ny,
n_tower, nt``, ``float32 dz, dy, dt, u_hub, z_hub, z_bottom``, then ``float32`` slope and
offset per component ``(u, v, w)``, ``int32 n_chars`` and that many ASCII characters of
description; then for every time step the grid as ``int16`` with the component fastest, then
``y``, then ``z``, followed by the tower points. A value is ``(int16 - offset) / slope`` in
m/s, full velocity (mean included). The grid ``y`` is centred on 0 (positive to the left
looking downwind), ``z = z_bottom + k dz`` above the ground. Time planes become space under
Taylor's hypothesis with the file's ``u_hub`` (or a given speed): the plane taken at
``t = n dt`` lies ``n dt U`` upstream of the plane at ``t = 0``.
"""

from __future__ import annotations

import dataclasses
import struct
from pathlib import Path

import jax.numpy as jnp
import numpy as np

from .._precision import default_float
from .._util import PathLike, atomic_path, file_error, require_file
from ..turbulence import TurbulenceBox

__all__ = [
    "read_hawc2_box",
    "write_hawc2_box",
    "TurbSimField",
    "read_turbsim",
    "write_turbsim",
]


def _shape3(shape, what: str) -> tuple[int, int, int]:
    try:
        out = tuple(int(n) for n in shape)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: `shape` must be three integers (nx, ny, nz), got {shape!r}.") from None
    if len(out) != 3 or any(n < 1 for n in out) or any(int(n) != n for n in shape):
        raise ValueError(f"{what}: `shape` must be three positive integers (nx, ny, nz), got {shape!r}.")
    return out


def _spacing3(spacing, what: str) -> np.ndarray:
    s = np.asarray(spacing, dtype=np.float64)
    if s.shape != (3,) or not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise ValueError(f"{what}: `spacing` must be (dx, dy, dz) in positive metres, got {spacing!r}.")
    return s


def read_hawc2_box(
    u: PathLike,
    v: PathLike,
    w: PathLike,
    shape: tuple[int, int, int],
    spacing: tuple[float, float, float],
    *,
    periodic: tuple[bool, bool] | bool = (False, False),
    reverse_x: bool = False,
    dtype=None,
):
    """Read a Mann box in HAWC2 binary (three float32 files) as a `TurbulenceBox`.

    **Arguments:**

    - `u`, `v`, `w`: the three component files (HAWC2 ``mann`` block ``filename_u/v/w``).
    - `shape`: ``(nx, ny, nz)``, HAWC2's ``box_dim_u/v/w`` point counts.
    - `spacing`: ``(dx, dy, dz)`` in metres (HAWC2's box length divided by the point count).
    - `periodic`: whether the box is periodic laterally and vertically (a Mann box made
      without doubling is; see `lidarjax.TurbulenceBox`).
    - `reverse_x`: reverse the ``x`` order (node ``i`` holds plane ``(-i) mod nx``), so that a
      point at the box's ``x = 0`` meets planes ``0, 1, 2, ...`` in time, as HAWC2/OpenFAST
      feed them to a turbine (see the module docs).
    - `dtype`: working dtype of the box (default: the configured default float).

    Raises `ValueError` naming the file when its size is not ``4 nx ny nz`` bytes (with the
    point count it does hold), or when it holds NaN or inf.
    """

    shape = _shape3(shape, "read_hawc2_box")
    s = _spacing3(spacing, "read_hawc2_box")
    n = shape[0] * shape[1] * shape[2]
    comps = []
    for name, path in (("u", u), ("v", v), ("w", w)):
        p = require_file(path, f"HAWC2 turbulence file ({name})")
        size = p.stat().st_size
        if size != 4 * n:
            raise file_error(
                p, None,
                f"a {shape[0]} x {shape[1]} x {shape[2]} box needs {4 * n} bytes ({n} float32), the file "
                f"has {size} bytes ({size / 4:g} values). Check the box dimensions (nx, ny, nz)."
            )
        data = np.fromfile(p, dtype="<f4").reshape(shape)
        if not np.all(np.isfinite(data)):
            raise file_error(p, None, "contains NaN or inf values.")
        comps.append(data)
    uvw = np.stack(comps, axis=-1)
    if reverse_x:  # node i holds plane (-i) mod nx: a fixed point meets planes 0, 1, 2, ...
        uvw = uvw[(-np.arange(shape[0])) % shape[0]]
    dtype = default_float() if dtype is None else dtype
    return TurbulenceBox(jnp.asarray(uvw, dtype=dtype), jnp.asarray(s, dtype=dtype), periodic=periodic)


def write_hawc2_box(box, u: PathLike, v: PathLike, w: PathLike) -> tuple[Path, Path, Path]:
    """Write a `TurbulenceBox` as three HAWC2 float32 files (atomically); returns the paths.
    Read it back with `read_hawc2_box(u, v, w, box.shape, spacing)`."""
    uvw = np.asarray(box.velocity, dtype="<f4")
    out = []
    for c, path in enumerate((u, v, w)):
        target = Path(path)
        with atomic_path(target) as tmp, open(tmp, "xb") as fh:
            fh.write(np.ascontiguousarray(uvw[..., c]).tobytes())
        out.append(target)
    return tuple(out)


@dataclasses.dataclass(frozen=True)
class TurbSimField:
    """A TurbSim full field as read from a ``.bts`` file (plain numpy).

    - `velocity`: ``(nt, ny, nz, 3)`` full velocities ``(u, v, w)`` in m/s (mean included),
      TurbSim's axes (``u`` downwind, ``v`` to the left looking downwind, ``w`` up).
    - `y`: ``(ny,)`` lateral coordinates (m, centred on 0); `z`: ``(nz,)`` heights (m).
    - `dt`: time step (s); `u_hub`, `z_hub`: the hub-height mean speed (m/s) and height (m).
    - `periodic`: the file's ID is 8 (the series is periodic in time).
    - `tower`: ``(nt, n_tower, 3)`` tower-line velocities below the grid (m/s), at heights
      ``z_bottom - k dz``.
    - `description`: the file's text.
    """

    velocity: np.ndarray
    y: np.ndarray
    z: np.ndarray
    dt: float
    u_hub: float
    z_hub: float
    periodic: bool
    tower: np.ndarray
    description: str

    @property
    def time(self) -> np.ndarray:
        """``(nt,)`` times of the planes, s."""
        return np.arange(self.velocity.shape[0]) * self.dt

    def box(self, speed: float | None = None, *, remove_mean: bool = True, dtype=None):
        """The fluctuations as a `TurbulenceBox` (Taylor: ``dx = speed dt``).

        - `speed`: the advection speed converting time to space (m/s); default `u_hub`, as
          OpenFAST's InflowWind does. Advect the box at the same speed in `FrozenTurbulence`.
        - `remove_mean`: subtract each grid point's time mean (the mean flow comes from
          `FrozenTurbulence`'s mean field); False keeps the full velocities.

        The plane taken at ``t = n dt`` lies ``n dt U`` upstream, so box node ``i`` (at
        ``x = i dx`` downwind) holds plane ``(-i) mod nt``: advected at ``U``, a point at box
        ``x = 0`` sees plane ``n`` at ``t = n dt``, as InflowWind's turbine does. The box is
        periodic along ``x``; laterally and vertically it covers the grid only (NaN outside);
        the grid bottom is box ``z = 0`` (place it with ``anchor`` at height `z[0]`).
        """

        u = float(self.u_hub if speed is None else speed)
        if not np.isfinite(u) or u <= 0:
            raise ValueError(
                f"TurbSimField.box: the advection speed must be positive m/s, got {u!r} "
                f"(the file's u_hub is {self.u_hub!r}); pass `speed`."
            )
        vel = self.velocity.astype(np.float64)
        if remove_mean:
            vel = vel - vel.mean(axis=0, keepdims=True)
        nt = vel.shape[0]
        vel = vel[(-np.arange(nt)) % nt]
        dy = float(self.y[1] - self.y[0]) if self.y.size > 1 else 1.0
        dz = float(self.z[1] - self.z[0]) if self.z.size > 1 else 1.0
        dtype = default_float() if dtype is None else dtype
        return TurbulenceBox(jnp.asarray(vel, dtype=dtype), jnp.asarray([u * self.dt, dy, dz], dtype=dtype),
                             periodic=(False, False))


_HEADER = struct.Struct("<h4l6f6fl")


def read_turbsim(path: PathLike) -> TurbSimField:
    """Read a TurbSim binary full-field file (``.bts``); see the module docs for the format.

    Raises `ValueError` naming the file for a truncated or inconsistent file (wrong ID,
    non-positive dimensions, zero slopes, a size that does not match the header).
    """
    p = require_file(path, "TurbSim file")
    raw = p.read_bytes()
    if len(raw) < _HEADER.size:
        raise file_error(p, None, f"too short for a TurbSim .bts header ({len(raw)} bytes).")
    (ident, nz, ny, ntwr, nt, dz, dy, dt, u_hub, z_hub, z_bottom,
     s_u, o_u, s_v, o_v, s_w, o_w, nchar) = _HEADER.unpack_from(raw, 0)
    if ident not in (7, 8):
        raise file_error(p, None, f"not a TurbSim full-field file: ID {ident}, expected 7 or 8.")
    if nz < 1 or ny < 1 or nt < 1 or ntwr < 0 or nchar < 0:
        raise file_error(p, None, f"bad dimensions nz={nz}, ny={ny}, nt={nt}, n_tower={ntwr}.")
    if not (dt > 0 and dz > 0 and dy > 0):
        raise file_error(p, None, f"bad spacings dz={dz}, dy={dy}, dt={dt} (must be positive).")
    slope = np.array([s_u, s_v, s_w], np.float64)
    offset = np.array([o_u, o_v, o_w], np.float64)
    if np.any(slope == 0) or not np.all(np.isfinite(slope)) or not np.all(np.isfinite(offset)):
        raise file_error(p, None, f"bad scaling slopes {slope.tolist()} / offsets {offset.tolist()}.")
    start = _HEADER.size + nchar
    per_step = 3 * (ny * nz + ntwr)
    need = start + 2 * per_step * nt
    if len(raw) != need:
        raise file_error(
            p, None,
            f"size {len(raw)} bytes does not match its header ({nt} steps of {ny} x {nz} points"
            f" + {ntwr} tower points need {need} bytes); the file is truncated or not a .bts file."
        )
    description = raw[_HEADER.size:start].decode("ascii", errors="replace")
    data = np.frombuffer(raw, dtype="<i2", count=per_step * nt, offset=start).reshape(nt, per_step)
    grid = data[:, : 3 * ny * nz].reshape(nt, nz, ny, 3).transpose(0, 2, 1, 3)
    tower = data[:, 3 * ny * nz:].reshape(nt, ntwr, 3)
    grid = (grid.astype(np.float64) - offset) / slope
    tower = (tower.astype(np.float64) - offset) / slope
    y = (np.arange(ny) - (ny - 1) / 2) * float(dy)
    z = float(z_bottom) + np.arange(nz) * float(dz)
    return TurbSimField(
        velocity=grid, y=y, z=z, dt=float(dt), u_hub=float(u_hub), z_hub=float(z_hub),
        periodic=ident == 8, tower=tower, description=description,
    )


def write_turbsim(
    path: PathLike,
    velocity,
    *,
    dy: float,
    dz: float,
    dt: float,
    z_bottom: float,
    u_hub: float,
    z_hub: float,
    periodic: bool = False,
    description: str = "written by lidarjax",
) -> Path:
    """Write a TurbSim ``.bts`` file (no tower points), atomically.

    `velocity` is ``(nt, ny, nz, 3)`` full velocities in m/s; each component is scaled to the
    full int16 range as TurbSim does (the round trip error is at most half a step, about
    ``range / 65535 / 2``). Returns the path.
    """
    vel = np.asarray(velocity, dtype=np.float64)
    if vel.ndim != 4 or vel.shape[-1] != 3:
        raise ValueError(f"write_turbsim: velocity must be (nt, ny, nz, 3), got {vel.shape}.")
    if not np.all(np.isfinite(vel)):
        raise ValueError("write_turbsim: velocity contains NaN or inf.")
    nt, ny, nz, _ = vel.shape
    lo, hi = vel.reshape(-1, 3).min(axis=0), vel.reshape(-1, 3).max(axis=0)
    slope = np.where(hi > lo, 65535.0 / np.where(hi > lo, hi - lo, 1.0), 1.0).astype(np.float32)
    offset = (-32768.0 - slope.astype(np.float64) * lo).astype(np.float32)
    ints = np.rint(vel * slope.astype(np.float64) + offset.astype(np.float64))
    ints = np.clip(ints, -32768, 32767).astype("<i2")
    text = description.encode("ascii", errors="replace")
    header = _HEADER.pack(8 if periodic else 7, nz, ny, 0, nt, dz, dy, dt, u_hub, z_hub, z_bottom,
                          slope[0], offset[0], slope[1], offset[1], slope[2], offset[2], len(text))
    body = np.ascontiguousarray(ints.transpose(0, 2, 1, 3)).tobytes()
    target = Path(path)
    with atomic_path(target) as tmp, open(tmp, "xb") as fh:
        fh.write(header + text + body)
    return target
