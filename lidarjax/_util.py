"""Shared non-public helpers of every layer: errors that name a file, atomic writes, optional
imports, key normalisation, number formatting, and `compiled` (small array functions as one
compiled program).

Nothing here is public API, and nothing here imports the rest of lidarjax: every module, from
the core to the command line, may use it.
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import math
import os
import re
import uuid
import weakref
from collections.abc import Iterator, Sequence
from pathlib import Path
from types import ModuleType

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

__all__: list[str] = []

PathLike = str | os.PathLike[str]


def compiled(fn):
    """`fn` (a function of arrays, or a method of an `equinox.Module`) compiled as one program
    per input structure (`equinox.filter_jit`: arrays dynamic, everything else static).

    Called outside `jax.jit`, JAX runs a chain of `jax.numpy` operations one by one and
    compiles each the first time it meets a shape (20-80 ms apiece on a CPU); a helper of
    twenty operations then takes a second on its first call. Compiled, it takes one
    compilation, and inside a trace it is inlined. Python numbers, lists and tuples, given
    by position or by keyword, are made arrays first, so a number is a dynamic input, never
    a static one that compiles again per value (`jax.jit` takes no lists); booleans,
    strings and ``None`` stay static."""
    jitted = eqx.filter_jit(fn)

    @functools.wraps(fn)
    def call(*args, **kwargs):
        return jitted(*map(_as_input, args), **{k: _as_input(v) for k, v in kwargs.items()})

    return call


def map_in_batches(fn, xs, batch_size: int):
    """``jax.lax.map(fn, xs, batch_size=batch_size)`` in equal batches: as many batches as
    that, each at most `batch_size` rows, the leading axis padded to whole batches (fewer
    rows than batches; copies of the first row, whose results are dropped). `lax.map` would
    trace and compile `fn` a second time for a remainder batch. `xs` a pytree of arrays; the
    same results, `fn` in one program."""
    n = jax.tree_util.tree_leaves(xs)[0].shape[0]
    if batch_size >= n:
        return jax.lax.map(fn, xs, batch_size=batch_size)
    n_batches = -(-n // batch_size)
    batch_size = -(-n // n_batches)
    pad = n_batches * batch_size - n
    if not pad:
        return jax.lax.map(fn, xs, batch_size=batch_size)
    xs = jax.tree_util.tree_map(
        lambda a: jnp.concatenate([a, jnp.repeat(a[:1], pad, axis=0)]), xs)
    out = jax.lax.map(fn, xs, batch_size=batch_size)
    return jax.tree_util.tree_map(lambda a: a[:n], out)


def _as_input(value):
    """A Python number, list or tuple as an array (a dynamic input of `compiled`)."""
    if isinstance(value, int | float | list | tuple) and not isinstance(value, bool):
        return jnp.asarray(value)
    return value


def file_error(path: PathLike, line: int | None, message: str) -> ValueError:
    """A `ValueError` whose message starts with the file and, when known, the 1-based line."""
    where = f"{os.fspath(path)}, line {line}" if line is not None else os.fspath(path)
    return ValueError(f"{where}: {message}")


def require_file(path: PathLike, what: str) -> Path:
    """Return `path` as a `Path`, raising `FileNotFoundError` naming it when it is not a file."""
    p = Path(path)
    if not p.is_file():
        if p.exists():
            raise FileNotFoundError(f"{what} {os.fspath(p)!s} is not a regular file")
        raise FileNotFoundError(f"{what} not found: {os.fspath(p)!s}")
    return p


def import_optional(module: str, extra: str, purpose: str) -> ModuleType:
    """Import an optional dependency, or raise an `ImportError` that names the pip extra."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ImportError(
            f"{purpose} needs the optional package '{module}', which is not installed: "
            f"pip install lidarjax[{extra}]"
        ) from err


def have_module(module: str) -> bool:
    """Whether `module` can be imported (without raising)."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True


def netcdf_engine() -> str:
    """`h5netcdf` (NetCDF4) when it and h5py are installed, else scipy's NetCDF3 writer."""
    return "h5netcdf" if have_module("h5netcdf") and have_module("h5py") else "scipy"


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a fresh temporary path beside `path`; on success move it onto `path` atomically.

    The temporary file lives in the same directory (so `os.replace` is atomic on POSIX
    and Windows) and keeps the final suffix (some writers dispatch on it). On any
    exception the temporary file is removed and `path` is left untouched.
    """
    target = Path(path)
    if not target.parent.is_dir():
        raise FileNotFoundError(f"directory not found: {os.fspath(target.parent)}")
    tmp = target.with_name(f".{target.name}.{uuid.uuid4().hex[:12]}.tmp{target.suffix}")
    try:
        yield tmp
        with open(tmp, "rb") as fh:  # flush the data to disk before the rename
            os.fsync(fh.fileno())
        os.replace(tmp, target)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def atomic_write_text(path: PathLike, text: str, *, encoding: str = "utf-8") -> Path:
    """Write `text` to `path` atomically (temporary file in the same directory, then rename)."""
    target = Path(path)
    with atomic_path(target) as tmp, open(tmp, "x", encoding=encoding, newline="\n") as fh:
        fh.write(text)
    return target


_UNIT_RE = re.compile(r"\([^)]*\)|\[[^\]]*\]")


_NON_ALNUM_RE = re.compile(r"[^0-9a-z]+")


def normalise_key(key: str) -> str:
    """Lower-case `key`, drop bracketed units and every non-alphanumeric character.

    `"ScanAngle (°)"`, `"Scan Angle(°)"` and `"scan_angle"` all become `"scanangle"`.
    """
    return _NON_ALNUM_RE.sub("", _UNIT_RE.sub("", key.lower()))


def freeze(a: np.ndarray) -> np.ndarray:
    """Mark an array read-only (records are immutable) and return it."""
    a.setflags(write=False)
    return a


def format_number(x: float) -> str:
    """Shortest text that reads back to the same float; integral values without '.0'."""
    xf = float(x)
    if math.isfinite(xf) and xf.is_integer() and abs(xf) < 1e15:
        return str(int(xf))
    return repr(xf)


def summarise_lines(lines: Sequence[int], limit: int = 8) -> str:
    """`'12, 40, 41'` or `'12, 40, ... (25 lines)'`."""
    shown = ", ".join(str(n) for n in lines[:limit])
    return shown if len(lines) <= limit else f"{shown}, ... ({len(lines)} lines)"


def nan_mean(values, axis=None):
    """``numpy.nanmean`` without its ``RuntimeWarning: Mean of empty slice``: the mean of the
    entries that are not NaN (along `axis`), NaN where there are none (an empty or all-NaN
    slice). For printed summaries, which then say why a value is NaN."""
    a = np.asarray(values, np.float64)
    given = ~np.isnan(a)
    n = np.count_nonzero(given, axis=axis)
    total = np.sum(np.where(given, a, 0.0), axis=axis)
    return np.where(n > 0, total / np.maximum(n, 1), np.nan)


def nan_max(values, axis=None):
    """``numpy.nanmax`` without its ``RuntimeWarning: All-NaN slice``: NaN where a slice is
    empty or all NaN."""
    a = np.asarray(values, np.float64)
    given = ~np.isnan(a)
    if a.size == 0:
        return np.max(a, axis=axis, initial=np.nan) if axis is not None else np.nan
    peak = np.max(np.where(given, a, -np.inf), axis=axis)
    return np.where(np.any(given, axis=axis), peak, np.nan)




class ArrayMemo:
    """Host-side results memoised on the *identity* of the JAX arrays they were computed from
    (a probe's nodes chosen for a field and ranges: `simulate` would otherwise redo that
    choice, and its device-to-host reads, on every call).

    JAX arrays are immutable, so the same objects give the same result. An entry is dropped
    as soon as any of its arrays is garbage-collected (weak references), so an identity is
    never reused for other values; at most `size` entries are kept (oldest dropped). Inputs
    holding anything but concrete JAX arrays (numpy arrays are mutable, tracers have no
    value) are not memoised: `compute` runs every time.
    """

    def __init__(self, size: int = 64):
        self._size = size
        self._entries: dict = {}

    def __call__(self, trees, compute):
        leaves, treedef = jax.tree_util.tree_flatten(trees)
        if not leaves or not all(isinstance(a, jax.Array) and not isinstance(a, jax.core.Tracer)
                                 for a in leaves):
            return compute()
        try:
            key = (treedef, tuple(id(a) for a in leaves))
            hash(key)
        except TypeError:  # unhashable static metadata
            return compute()
        hit = self._entries.get(key)
        if hit is not None and all(r() is a for r, a in zip(hit[0], leaves, strict=True)):
            return hit[1]
        value = compute()
        drop = lambda _ref, k=key: self._entries.pop(k, None)  # noqa: E731
        refs = tuple(weakref.ref(a, drop) for a in leaves)
        while len(self._entries) >= self._size:
            try:  # a weak reference's callback may drop entries meanwhile
                self._entries.pop(next(iter(self._entries)), None)
            except (RuntimeError, StopIteration):
                break
        self._entries[key] = (refs, value)
        return value
