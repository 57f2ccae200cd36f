"""The seed UDF's `settings.dat`: reader, writer and the `Settings` record.

The seed Fluent UDF (Stickland, Fabre & Scanlon 2011, section 6) reads a small
whitespace-separated text file:

```
zone    verbose height  nh      gamma   beta    psi     epsilon
2       0       1.0     50      0.0     330.0   180.0   21.0
0       3.9316  3.4358  0.355
30      3.9235  3.4343  0.355
...
330     3.9358  3.1483  0.355
```

- line 1: eight header words (their spelling is not checked);
- line 2: `zone` (Fluent fluid-zone id, integer), `verbose` (0 abbreviated output,
  1 verbose output with a header line), `height` (m, range above the lidar over which
  heights are interrogated), `nh` (number of heights, positive integer), and four
  angles in degrees: `gamma` (lidar to rig), `beta` (free-stream direction relative
  to the rig, the platform rotation being simulated), `psi` (CFD to lidar) and
  `epsilon` (software rotation to north);
- then one row `beta x y z` per platform rotation: the lidar location (m) in the
  CFD frame when the free stream comes at that `beta` (degrees).

**Explicit heights (a lidarjax extension).** A lidar's configured altitudes (a Windcube's
40, 54, 74 ... m) are rarely `j * height / nh`. After the values line, a line starting with
the word `heights` may list them, in metres above the lidar, strictly increasing:

```
heights 40      54      74      94      114
```

`nh` must then equal the number of heights and `height` the top one, so the values line
stays true. Files without the line read exactly as before (heights `j * height / nh`). The
seed C code does not know this line; keep it out of files meant for the UDF.

`nh` (or the number of explicit heights) is limited to `MAX_HEIGHTS` = 1000, far above any
lidar, so that a typo cannot start a computation that runs for hours.

The C code skipped `beta / 30` rows to find the location, which only works for a
30 degree spacing with rows in order from 0. Here rows are looked up by their beta
value (modulo 360, tolerance `BETA_TOLERANCE_DEG`), so any sector spacing and any row
order work. Tabs or spaces separate fields; blank lines are ignored.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

import numpy as np
from jaxtyping import Float

from .._util import PathLike, atomic_write_text, file_error, format_number, freeze, require_file
from ._common import is_number

__all__ = [
    "BETA_TOLERANCE_DEG",
    "MAX_HEIGHTS",
    "SETTINGS_HEADER",
    "Settings",
    "read_settings",
    "write_settings",
]

BETA_TOLERANCE_DEG = 1e-6
"""Two betas closer than this (degrees, modulo 360) name the same location row."""

MAX_HEIGHTS = 1000
"""The most heights a settings file may ask for (`nh`, or explicit heights)."""

SETTINGS_HEADER: tuple[str, ...] = (
    "zone",
    "verbose",
    "height",
    "nh",
    "gamma",
    "beta",
    "psi",
    "epsilon",
)
"""The header words of the seed's `settings.dat` (table 2 of the seed report)."""


def _angle_gap(a: np.ndarray | float, b: np.ndarray | float) -> np.ndarray:
    """Absolute angular distance in degrees, in [0, 180]."""
    return np.abs((np.asarray(a, dtype=np.float64) - b + 180.0) % 360.0 - 180.0)


def _format_betas(betas: np.ndarray) -> str:
    return ", ".join(format_number(b) for b in betas)


@dataclasses.dataclass(frozen=True, eq=False)
class Settings:
    """The contents of a seed `settings.dat` file.

    **Fields:**

    - `zone`: Fluent fluid-zone id.
    - `verbose`: 0 (abbreviated output, no header line) or 1 (verbose, header line).
    - `height`: metres; heights `j * height / nh`, `j = 1..nh`, are interrogated above
      the lidar.
    - `nh`: number of heights (positive integer).
    - `gamma`, `beta`, `psi`, `epsilon`: degrees (see the module docstring); `beta` is the
      platform rotation this run simulates.
    - `betas`: `(s,)` degrees, the beta of each location row, in file order.
    - `locations`: `(s, 3)` metres, the lidar location `(x, y, z)` in the CFD frame for
      each row.
    - `header`: the header words as written in the file.
    - `source`: the file this was read from (for error messages), or `None`.
    - `explicit_heights`: `(nh,)` metres above the lidar, strictly increasing, or `None`
      for the seed's `j * height / nh` (see the module docstring).

    Arrays are stored read-only. Construction validates the values and raises
    `ValueError` naming the fix.
    """

    zone: int
    verbose: int
    height: float
    nh: int
    gamma: float
    beta: float
    psi: float
    epsilon: float
    betas: Float[np.ndarray, " s"]
    locations: Float[np.ndarray, "s 3"]
    header: tuple[str, ...] = SETTINGS_HEADER
    source: str | None = None
    explicit_heights: Float[np.ndarray, " h"] | None = None

    def __post_init__(self) -> None:
        where = f"{self.source}: " if self.source else ""
        if self.verbose not in (0, 1):
            raise ValueError(f"{where}verbose must be 0 or 1, got {self.verbose!r}")
        if isinstance(self.nh, bool) or int(self.nh) != self.nh or self.nh < 1:
            raise ValueError(f"{where}nh must be a positive integer, got {self.nh!r}")
        if self.nh > MAX_HEIGHTS:
            raise ValueError(f"{where}nh = {self.nh} heights is more than the limit of "
                             f"{MAX_HEIGHTS}; a lidar measures a few dozen at most")
        if self.explicit_heights is not None:
            eh = np.array(self.explicit_heights, dtype=np.float64).reshape(-1)
            if eh.size == 0 or not np.all(np.isfinite(eh)) or np.any(eh <= 0):
                raise ValueError(f"{where}explicit heights must be finite and > 0 m, got "
                                 f"{eh.tolist()}")
            if np.any(np.diff(eh) <= 0):
                raise ValueError(f"{where}explicit heights must be strictly increasing, got "
                                 f"{eh.tolist()}")
            if eh.size != int(self.nh) or not math.isclose(float(eh[-1]), float(self.height),
                                                             rel_tol=1e-9):
                raise ValueError(
                    f"{where}the values line (height {format_number(float(self.height))}, nh "
                    f"{self.nh}) disagrees with the {eh.size} explicit heights; set height to "
                    f"{format_number(float(eh[-1]))} and nh to {eh.size}")
            object.__setattr__(self, "explicit_heights", freeze(eh))
        for name in ("height", "gamma", "beta", "psi", "epsilon"):
            if not math.isfinite(float(getattr(self, name))):
                raise ValueError(f"{where}{name} must be finite, got {getattr(self, name)!r}")
        if not float(self.height) > 0.0:
            raise ValueError(f"{where}height must be > 0 m, got {self.height!r}")
        betas = np.array(self.betas, dtype=np.float64).reshape(-1)
        locations = np.array(self.locations, dtype=np.float64)
        if locations.ndim != 2 or locations.shape != (betas.size, 3):
            raise ValueError(
                f"{where}locations must have shape (s, 3) = ({betas.size}, 3) to match "
                f"betas, got {locations.shape}"
            )
        if betas.size == 0:
            raise ValueError(f"{where}at least one location row 'beta x y z' is needed")
        if not (np.all(np.isfinite(betas)) and np.all(np.isfinite(locations))):
            raise ValueError(f"{where}betas and locations must be finite")
        gaps = _angle_gap(betas[:, None], betas[None, :])
        np.fill_diagonal(gaps, np.inf)
        if np.any(gaps <= BETA_TOLERANCE_DEG):
            i, j = np.argwhere(gaps <= BETA_TOLERANCE_DEG)[0]
            raise ValueError(
                f"{where}duplicate location rows for beta {format_number(betas[i])} and "
                f"{format_number(betas[j])} (same angle modulo 360); keep one row per beta"
            )
        object.__setattr__(self, "zone", int(self.zone))
        object.__setattr__(self, "verbose", int(self.verbose))
        object.__setattr__(self, "nh", int(self.nh))
        for name in ("height", "gamma", "beta", "psi", "epsilon"):
            object.__setattr__(self, name, float(getattr(self, name)))
        object.__setattr__(self, "betas", freeze(betas))
        object.__setattr__(self, "locations", freeze(locations))
        object.__setattr__(self, "header", tuple(str(w) for w in self.header))

    def has_location(self, beta: float) -> bool:
        """Whether a location row exists for `beta` (degrees, compared modulo 360)."""
        return bool(np.any(_angle_gap(self.betas, float(beta)) <= BETA_TOLERANCE_DEG))

    def location(self, beta: float | None = None) -> Float[np.ndarray, " 3"]:
        """The lidar location `(x, y, z)` in metres, CFD frame, for platform rotation `beta`.

        **Arguments:**

        - `beta`: degrees; defaults to `self.beta`. Matched against the rows' betas modulo
          360 within `BETA_TOLERANCE_DEG`, so `-30` finds the `330` row.

        **Returns:** a float64 array of shape `(3,)`.

        Raises `ValueError` listing the available betas when no row matches.
        """
        b = self.beta if beta is None else float(beta)
        hits = np.flatnonzero(_angle_gap(self.betas, b) <= BETA_TOLERANCE_DEG)
        if hits.size == 0:
            where = f"{self.source}: " if self.source else ""
            raise ValueError(
                f"{where}no location row for beta = {format_number(b)} degrees; "
                f"rows exist for betas {_format_betas(self.betas)}"
            )
        return self.locations[hits[0]].copy()

    def heights(self) -> Float[np.ndarray, " h"]:
        """Interrogation heights above the lidar, metres: the explicit heights when the file
        lists them, else `h_j = j * height / nh`, j = 1..nh."""
        if self.explicit_heights is not None:
            return np.array(self.explicit_heights, dtype=np.float64)
        return np.arange(1, self.nh + 1, dtype=np.float64) * self.height / self.nh

    def with_heights(self, heights) -> Settings:
        """A copy measuring at explicit `heights` (m above the lidar, strictly increasing);
        `height` and `nh` follow them."""
        h = np.asarray(heights, dtype=np.float64).reshape(-1)
        if h.size == 0:
            raise ValueError("with_heights: at least one height is needed")
        return dataclasses.replace(self, height=float(h[-1]), nh=int(h.size),
                                   explicit_heights=h)


def _tokens(raw: str) -> list[str]:
    return raw.split()


def _number(path: Path, line: int, name: str, text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        raise file_error(path, line, f"{name}: expected a number, found {text!r}") from None
    if not math.isfinite(value):
        raise file_error(path, line, f"{name}: expected a finite number, found {text!r}")
    return value


def _integer(path: Path, line: int, name: str, text: str, *, positive: bool = False) -> int:
    value = _number(path, line, name, text)
    if not value.is_integer() or (positive and value < 1):
        kind = "a positive integer" if positive else "an integer"
        raise file_error(path, line, f"{name}: expected {kind}, found {text!r}")
    return int(value)


def read_settings(path: PathLike) -> Settings:
    """Read a seed `settings.dat` file (format in the module docstring).

    **Arguments:**

    - `path`: the file.

    **Returns:** a `Settings`. Its `beta` must have a location row.

    Raises `FileNotFoundError` naming the path when it is missing, and `ValueError`
    naming the file, the line and what was expected for: a numeric header line (header
    missing), a wrong number of fields, a non-numeric field, `zone` not an integer,
    `verbose` not 0/1, `nh` not a positive integer (`50` and `50.0` are both fine),
    duplicate beta rows, no location rows, and no row for the file's `beta` (the
    message lists the betas present).
    """
    p = require_file(path, "settings file")
    lines = _token_lines(p)
    header_line, header = lines[0]
    if len(header) == len(SETTINGS_HEADER) and all(is_number(t) for t in header):
        raise file_error(
            p,
            header_line,
            "expected the header line of 8 words (" + " ".join(SETTINGS_HEADER) + ") "
            "before the values; found 8 numbers",
        )
    if len(lines) < 2:
        raise file_error(p, None, "expected a values line after the header; the file ends")
    vline, values = lines[1]
    numbers = _values_line(p, vline, values)
    betas, locations, explicit = _location_rows(p, lines[2:], numbers, values, vline)
    settings = Settings(
        **numbers,
        betas=np.asarray(betas),
        locations=np.asarray(locations),
        header=tuple(header),
        source=str(p),
        explicit_heights=None if explicit is None else np.asarray(explicit),
    )
    if not settings.has_location(numbers["beta"]):
        raise file_error(
            p,
            vline,
            f"no location row for the beta of this line ({values[5]} degrees); rows exist "
            f"for betas {_format_betas(settings.betas)}",
        )
    return settings


def _token_lines(p: Path) -> list[tuple[int, list[str]]]:
    """The file's non-blank lines as `(1-based line, whitespace-separated words)`."""
    lines: list[tuple[int, list[str]]] = []
    with open(p, encoding="utf-8", errors="replace") as fh:
        for number, raw in enumerate(fh, start=1):
            toks = _tokens(raw)
            if toks:
                lines.append((number, toks))
    if not lines:
        raise file_error(p, None, "empty file; expected a header line, a values line and rows")
    return lines


def _values_line(p: Path, vline: int, values: list[str]) -> dict[str, int | float]:
    """The eight numbers of the values line (`zone verbose height nh gamma beta psi
    epsilon`), each checked."""
    if len(values) != 8:
        raise file_error(
            p,
            vline,
            "expected 8 values (zone verbose height nh gamma beta psi epsilon), "
            f"found {len(values)}",
        )
    zone = _integer(p, vline, "zone", values[0])
    verbose = _integer(p, vline, "verbose", values[1])
    if verbose not in (0, 1):
        raise file_error(p, vline, f"verbose: expected 0 or 1, found {values[1]!r}")
    height = _number(p, vline, "height", values[2])
    if height <= 0:
        raise file_error(p, vline, f"height: expected a length > 0 m, found {values[2]!r}")
    nh = _integer(p, vline, "nh", values[3], positive=True)
    if nh > MAX_HEIGHTS:
        raise file_error(p, vline, f"nh: {values[3]} heights is more than the limit of "
                         f"{MAX_HEIGHTS}; a lidar measures a few dozen heights at most")
    gamma, beta, psi, epsilon = (
        _number(p, vline, name, text)
        for name, text in zip(("gamma", "beta", "psi", "epsilon"), values[4:], strict=True)
    )
    return dict(zone=zone, verbose=verbose, height=height, nh=nh, gamma=gamma, beta=beta,
                psi=psi, epsilon=epsilon)


def _location_rows(
    p: Path, lines: list[tuple[int, list[str]]], numbers: dict, values: list[str], vline: int,
) -> tuple[list[float], list[tuple[float, float, float]], list[float] | None]:
    """`(betas, locations, explicit heights or None)` from the lines after the values line."""
    betas: list[float] = []
    locations: list[tuple[float, float, float]] = []
    row_lines: list[int] = []
    explicit: list[float] | None = None
    for number, toks in lines:
        if toks[0].lower() == "heights":
            if explicit is not None:
                raise file_error(p, number, "a second 'heights' line; keep one")
            explicit = _explicit_heights(p, number, toks, numbers, values, vline)
            continue
        if len(toks) != 4:
            raise file_error(p, number, f"expected 4 fields 'beta x y z', found {len(toks)}")
        b, x, y, z = (
            _number(p, number, name, t) for name, t in zip("beta x y z".split(), toks, strict=True)
        )
        for previous, prev_line in zip(betas, row_lines, strict=True):
            if _angle_gap(previous, b) <= BETA_TOLERANCE_DEG:
                raise file_error(
                    p,
                    number,
                    f"duplicate location row for beta {toks[0]} (already given on line "
                    f"{prev_line}); keep one row per beta",
                )
        betas.append(b)
        locations.append((x, y, z))
        row_lines.append(number)
    if not betas:
        raise file_error(p, None, "expected location rows 'beta x y z' after the values line")
    return betas, locations, explicit


def _explicit_heights(
    p: Path, number: int, toks: list[str], numbers: dict, values: list[str], vline: int,
) -> list[float]:
    """The metres of a `heights` line, checked against the values line's `height` and `nh`."""
    explicit = [_number(p, number, "heights", t) for t in toks[1:]]
    if not explicit:
        raise file_error(p, number, "'heights' needs at least one height in metres")
    if len(explicit) > MAX_HEIGHTS:
        raise file_error(p, number, f"{len(explicit)} heights is more than the limit "
                         f"of {MAX_HEIGHTS}")
    if any(h <= 0 for h in explicit) or any(
            b <= a for a, b in zip(explicit, explicit[1:], strict=False)):
        raise file_error(p, number, "heights must be > 0 m and strictly increasing")
    if len(explicit) != numbers["nh"] or not math.isclose(explicit[-1], numbers["height"],
                                                          rel_tol=1e-9):
        raise file_error(
            p, number, f"the values line says height {values[2]} and nh {values[3]}, "
            f"but {len(explicit)} heights up to {format_number(explicit[-1])} m are "
            f"listed; set height to {format_number(explicit[-1])} and nh to "
            f"{len(explicit)} on line {vline}")
    return explicit


def write_settings(path: PathLike, settings: Settings) -> Path:
    """Write `settings` as a seed `settings.dat` (tab separated), atomically.

    Numbers are written in their shortest exact form, so `read_settings` returns the
    same values. Returns the path written.
    """
    def row(items: list[str]) -> str:
        return "\t".join(items) + "\n"

    text = row(list(settings.header) if len(settings.header) == 8 else list(SETTINGS_HEADER))
    text += row(
        [
            str(settings.zone),
            str(settings.verbose),
            format_number(settings.height),
            str(settings.nh),
            *(format_number(v) for v in (settings.gamma, settings.beta, settings.psi,
                                         settings.epsilon)),
        ]
    )
    if settings.explicit_heights is not None:
        text += row(["heights", *(format_number(h) for h in settings.explicit_heights)])
    for b, loc in zip(settings.betas, settings.locations, strict=True):
        text += row([format_number(b), *(format_number(v) for v in loc)])
    return atomic_write_text(path, text)
