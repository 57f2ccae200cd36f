"""Platform motion logs (a buoy's or ship's motion sensor) as `lidarjax.SampledMotion`.

CSV layout: optional ``#`` comment lines, one header line naming the columns, then numeric
rows separated by commas. Columns (case-insensitive, any order; missing degrees of freedom
are zero): ``time`` (seconds, strictly increasing), ``surge``, ``sway``, ``heave`` (metres,
in the lidar frame at rest: surge along ``+y`` towards beam S0, sway along ``+x`` towards
S1, heave up), ``pitch``, ``roll``, ``yaw`` (degrees, the conventions of `lidarjax.Mount`
and `lidarjax.motion`). A unit in brackets after a name (``pitch [deg]``) is ignored.
"""

from __future__ import annotations

import re

import numpy as np

from .._util import PathLike, file_error, require_file
from ..motion import SampledMotion

__all__ = ["read_motion_csv"]

_DOF = ("surge", "sway", "heave", "pitch", "roll", "yaw")


def read_motion_csv(path: PathLike):
    """Read a motion log (see the module docs) as a `lidarjax.motion.SampledMotion`.

    Raises `ValueError` naming the file (and line) for a missing ``time`` column, unknown
    columns, non-numeric cells or times that do not increase."""

    p = require_file(path, "motion CSV")
    lines = p.read_text(encoding="utf-8-sig").splitlines()
    rows = [(i + 1, ln) for i, ln in enumerate(lines) if ln.strip() and not ln.lstrip().startswith("#")]
    if not rows:
        raise file_error(p, None, "no header line (expected e.g. 'time,surge,sway,heave,pitch,roll,yaw')")
    hline, header = rows[0]
    names = [re.sub(r"\[.*?\]|\(.*?\)", "", c).strip().lower() for c in header.split(",")]
    unknown = [n for n in names if n not in ("time",) + _DOF]
    if unknown or "time" not in names:
        raise file_error(p, hline, f"columns must be 'time' and any of {', '.join(_DOF)}; got "
                                   f"{', '.join(names)}")
    data = []
    for ln, text in rows[1:]:
        cells = text.split(",")
        if len(cells) != len(names):
            raise file_error(p, ln, f"{len(cells)} cells for {len(names)} columns")
        try:
            data.append([float(c) for c in cells])
        except ValueError:
            raise file_error(p, ln, f"non-numeric cell in {text.strip()!r}") from None
    a = np.asarray(data, dtype=np.float64).reshape(-1, len(names))
    if a.shape[0] < 2:
        raise file_error(p, None, "need at least 2 rows of motion")
    col = {n: a[:, i] for i, n in enumerate(names)}
    t = col["time"]
    if not np.all(np.diff(t) > 0):
        bad = int(np.argmin(np.diff(t) > 0))
        raise file_error(p, rows[bad + 2][0], "times must increase strictly")
    zero = np.zeros_like(t)
    offset = np.stack([col.get("sway", zero), col.get("surge", zero), col.get("heave", zero)], -1)
    attitude = np.stack([col.get("pitch", zero), col.get("roll", zero), col.get("yaw", zero)], -1)
    if not (np.all(np.isfinite(offset)) and np.all(np.isfinite(attitude))):
        raise file_error(p, None, "motion values must be finite")
    return SampledMotion(t, offset, attitude)
