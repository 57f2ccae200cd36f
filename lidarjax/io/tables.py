"""Response-table files: `save_table` and `load_table` (NumPy ``.npz``).

A table file holds the arrays a `lidarjax.ResponseTable` is built from (directions in
meteorological degrees, LOS per unit free-stream speed, and the optional reconstructed,
point and beam responses, beam vectors and heights), plus a JSON metadata dictionary (scan,
mount angles, probe, source files). The spline coefficients are refitted on load, so a file
is independent of the lidarjax version that wrote it.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ._common import PathLike, atomic_path, file_error, require_file

__all__ = ["save_table", "load_table", "TABLE_FORMAT"]

TABLE_FORMAT = "lidarjax-response-table-1"
_OPTIONAL = ("reconstructed", "point", "beam_velocity", "beam_vectors", "heights")


def save_table(path: PathLike, table, metadata: dict[str, Any] | None = None) -> Path:
    """Write `table` (a `lidarjax.ResponseTable`) and JSON-serialisable `metadata` to
    `path` (``.npz``), atomically. Returns the path."""
    arrays = {"directions": np.asarray(table.directions), "response": np.asarray(table.response)}
    for name in _OPTIONAL:
        value = getattr(table, name)
        if value is not None:
            arrays[name] = np.asarray(value)
    meta = {"format": TABLE_FORMAT, **(metadata or {})}
    arrays["metadata"] = np.asarray(json.dumps(meta, default=float))
    target = Path(path)
    with atomic_path(target) as tmp, open(tmp, "xb") as fh:
        np.savez(fh, **arrays)
    return target


def load_table(path: PathLike, *, return_metadata: bool = False):
    """Read a table file written by `save_table`.

    **Returns:** the `lidarjax.ResponseTable` (in the file's dtype), or
    ``(table, metadata)`` with `return_metadata=True`. Raises `ValueError` naming the file
    for anything that is not such a table.
    """
    from ..response import ResponseTable

    p = require_file(path, "response table")
    try:
        data = np.load(p, allow_pickle=False)
    except Exception as err:  # noqa: BLE001 - any unreadable file gets the same message
        raise file_error(p, None, f"not a NumPy .npz table file ({err})") from None
    with data:
        if "metadata" not in data or "response" not in data or "directions" not in data:
            raise file_error(p, None, "not a lidarjax table: expected arrays 'directions', "
                             "'response' and 'metadata' (write it with lidarjax table)")
        meta = json.loads(str(data["metadata"]))
        if meta.get("format") != TABLE_FORMAT:
            raise file_error(p, None, f"unknown table format {meta.get('format')!r}, expected "
                             f"{TABLE_FORMAT!r}")
        kwargs = {n: data[n] for n in _OPTIONAL if n in data}
        table = ResponseTable(data["directions"], data["response"], **kwargs)
    return (table, meta) if return_metadata else table
