"""Response-table files: `save_table` and `load_table` (NumPy ``.npz``).

A table file holds the arrays a `lidarjax.ResponseTable` is built from (directions in
meteorological degrees, LOS per unit free-stream speed, and the optional reconstructed,
point and beam responses, beam vectors, the velocity gradient along the beams
(``beam_gradient``, for `lidarjax.calibrate`) and heights), plus a JSON metadata dictionary (scan,
mount angles, probe, source files). The spline coefficients are refitted on load, so a file
is independent of the lidarjax version that wrote it.

A `lidarjax.ProfileTable` (directions x one inflow-profile parameter) is written in format
`PROFILE_TABLE_FORMAT`: the per-profile arrays gain a leading ``(p,)`` axis, ``parameters``
holds the parameter values, and the metadata names the parameter (``parameter_name``) and the
profile (``profile``: ``{"kind": "power_law", "reference_height_m": ...}`` or
``{"kind": "uniform"}``). `load_table` reads both formats.
"""

from __future__ import annotations

import json
import math
import os
import zipfile
from pathlib import Path
from typing import Any

import numpy as np

from .._util import PathLike, atomic_path, file_error, require_file
from ..response import Instrument, ProfileTable, ResponseTable, profile_from_metadata

__all__ = ["save_table", "load_table", "TABLE_FORMAT", "PROFILE_TABLE_FORMAT"]

TABLE_FORMAT = "lidarjax-response-table-1"
PROFILE_TABLE_FORMAT = "lidarjax-profile-table-1"
_OPTIONAL = ("reconstructed", "point", "beam_velocity", "beam_vectors", "beam_gradient",
             "heights")
_PER_PROFILE = ("response", "reconstructed", "point", "beam_velocity", "beam_gradient")


def save_table(path: PathLike, table, metadata: dict[str, Any] | None = None) -> Path:
    """Write `table` (a `lidarjax.ResponseTable` or `lidarjax.ProfileTable`) and
    JSON-serialisable `metadata` to `path` (``.npz``), atomically. Returns the path."""
    own = {} if table.instrument is None else table.instrument.metadata()
    if isinstance(table, ProfileTable):
        t0 = table.tables[0]
        arrays = {"directions": np.asarray(table.directions),
                  "parameters": np.asarray(table.parameters)}
        for name in _PER_PROFILE:
            if getattr(t0, name) is not None:
                arrays[name] = np.stack([np.asarray(getattr(t, name)) for t in table.tables])
        for name in ("beam_vectors", "heights"):
            if getattr(t0, name) is not None:
                arrays[name] = np.asarray(getattr(t0, name))
        fixed = {"format": PROFILE_TABLE_FORMAT, "parameter_name": table.name,
                 "profile": table.profile.metadata()}
    else:
        arrays = {"directions": np.asarray(table.directions),
                  "response": np.asarray(table.response)}
        for name in _OPTIONAL:
            value = getattr(table, name)
            if value is not None:
                arrays[name] = np.asarray(value)
        fixed = {}
    meta = {"format": TABLE_FORMAT, **own, **(metadata or {}), **fixed}
    arrays["metadata"] = np.asarray(json.dumps(meta, default=float))
    target = Path(path)
    with atomic_path(target) as tmp, open(tmp, "xb") as fh:
        np.savez(fh, **arrays)
    return target


def load_table(path: PathLike, *, return_metadata: bool = False):
    """Read a table file written by `save_table`.

    **Returns:** the `lidarjax.ResponseTable` or, for a table over directions x a profile
    parameter, the `lidarjax.ProfileTable` (in the file's dtype), or ``(table, metadata)``
    with `return_metadata=True`. Raises `ValueError` naming the file
    for anything that is not such a table.
    """

    p = require_file(path, "response table")
    with open(p, "rb") as fh:  # our handle: closed even when numpy gives up half-way
        try:
            data = np.load(fh, allow_pickle=False)
        except Exception as err:  # noqa: BLE001 - any unreadable file gets the same message
            raise file_error(p, None, f"not a NumPy .npz table file ({err}); write it with "
                             "lidarjax table") from None
        if not hasattr(data, "files"):
            raise file_error(p, None, "a single NumPy array, not a lidarjax table (.npz); "
                             "write it with lidarjax table")
        try:
            with data:
                if "metadata" not in data or "response" not in data or "directions" not in data:
                    raise file_error(p, None, "not a lidarjax table: expected arrays "
                                     "'directions', 'response' and 'metadata' (write it with "
                                     "lidarjax table)")
                meta = _metadata(p, data["metadata"])
                arrays = {n: data[n] for n in ("directions", "response", "parameters",
                                               *_OPTIONAL) if n in data}
        except (OSError, EOFError, zipfile.BadZipFile, KeyError, ValueError) as err:
            if isinstance(err, ValueError) and str(err).startswith(os.fspath(p)):
                raise  # our own message
            raise file_error(p, None, f"corrupt table file ({err or type(err).__name__}); "
                             "build it again with lidarjax table") from None
    for name, a in arrays.items():
        if not (np.issubdtype(a.dtype, np.floating) or np.issubdtype(a.dtype, np.integer)) \
                or a.dtype == np.float16:
            raise file_error(p, None, f"array {name!r} has dtype {a.dtype}; a table holds real "
                             "float32/float64 numbers (build it again with lidarjax table)")
    try:
        instrument = Instrument.from_metadata(meta)
        if meta["format"] == PROFILE_TABLE_FORMAT:
            table = _profile_table(p, meta, arrays, instrument)
        else:
            arrays.pop("parameters", None)
            table = ResponseTable(arrays.pop("directions"), arrays.pop("response"), **arrays,
                                  instrument=instrument)
    except (ValueError, KeyError, TypeError, IndexError) as err:
        raise file_error(p, None, f"inconsistent table ({err})") from None
    return (table, meta) if return_metadata else table


def _profile_table(p: Path, meta: dict, arrays: dict, instrument) -> ProfileTable:
    name, prof = meta.get("parameter_name"), meta.get("profile")
    if not isinstance(name, str) or not isinstance(prof, dict) or "parameters" not in arrays:
        raise ValueError("a profile table needs 'parameters', and metadata 'parameter_name' "
                         "and 'profile'")
    values = np.asarray(arrays.pop("parameters"), np.float64).reshape(-1)
    directions = arrays.pop("directions")
    shared = {n: arrays[n] for n in ("beam_vectors", "heights") if n in arrays}
    for n in _PER_PROFILE:
        if n in arrays and arrays[n].shape[:1] != values.shape:
            raise ValueError(f"array {n!r} has {arrays[n].shape[:1]} profiles, 'parameters' "
                             f"{values.size}")
    tables = [ResponseTable(directions, arrays["response"][k],
                            **{n: arrays[n][k] for n in _PER_PROFILE[1:] if n in arrays},
                            **shared, instrument=instrument) for k in range(values.size)]
    return ProfileTable(name, values, tables, profile=profile_from_metadata(prof))


#: Metadata keys `lidarjax correct` relies on, with the types they must have.
_META_TYPES: dict[str, tuple[type, ...]] = {
    "scan": (str,), "scan_method": (str,), "probe": (str,), "settings": (str,), "field": (str,),
    "cone_angle_deg": (int, float), "gamma_deg": (int, float), "psi_deg": (int, float),
    "epsilon_deg": (int, float), "pitch_deg": (int, float), "roll_deg": (int, float),
    "probe_scale": (int, float), "n_beams": (int,), "vertical_beam": (bool,),
    "heights_m": (list,), "beam_azimuths_deg": (list,), "cfd_files": (dict,),
}


def _metadata(path: Path, raw: np.ndarray) -> dict[str, Any]:
    """The table's JSON metadata, checked: a dict whose known keys have the right types."""
    if raw.dtype.kind not in "US" or raw.shape != ():
        raise file_error(path, None, "the 'metadata' array must be one JSON text; build the "
                         "table again with lidarjax table")
    try:
        meta = json.loads(str(raw))
    except json.JSONDecodeError as err:
        raise file_error(path, None, f"metadata is not valid JSON ({err}); build the table "
                         "again with lidarjax table") from None
    if not isinstance(meta, dict):
        raise file_error(path, None, f"metadata must be a JSON object, found "
                         f"{type(meta).__name__}; build the table again with lidarjax table")
    if meta.get("format") not in (TABLE_FORMAT, PROFILE_TABLE_FORMAT):
        raise file_error(path, None, f"unknown table format {meta.get('format')!r}, expected "
                         f"{TABLE_FORMAT!r} or {PROFILE_TABLE_FORMAT!r}")
    for key, types in _META_TYPES.items():
        if key in meta and meta[key] is not None:
            value = meta[key]
            ok = isinstance(value, types) and not (bool not in types and isinstance(value, bool))
            if ok and isinstance(value, (int, float)) and not math.isfinite(float(value)):
                ok = False
            if ok and key == "heights_m":
                ok = all(isinstance(h, (int, float)) and not isinstance(h, bool) for h in value)
            if not ok:
                want = " or ".join(t.__name__ for t in types)
                raise file_error(path, None, f"metadata {key!r} must be {want}, found "
                                 f"{value!r}; build the table again with lidarjax table")
    return meta
