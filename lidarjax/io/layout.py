"""Wind-farm layouts in seed 004's format, turbine types, and probe-point files.

**Layout files** (seed 004, zCFD's ``<xy_file>``): one turbine per line,
``<name> <easting> <northing>`` separated by whitespace (or commas), metres in a projected
(UTM) frame; blank lines and ``#`` comments are skipped. Names must be unique.

**Turbine types**: FLORIS turbine-library or windIO turbine YAML files (`read_turbine_type`),
or a CSV of the thrust curve with the type's geometry in ``#`` header lines::

    # rotor_diameter = 126      (m; also: diameter, rotor_diameter_m)
    # hub_height = 90           (m above the ground; also: hub_height_m)
    speed,ct                    (m/s and Ct; also: wind_speed / speed_m_s, thrust_coefficient)
    3.0,0.0
    4.0,0.81
    ...

Each layout file is paired with one turbine type (`read_farm`): the zCFD utility's
``turbine_files=[[xy_file, trbx_file], ...]``.

**Probe points** (seed 004's generated monitor probes): `lidarjax farm` writes each turbine's
hub centre and reference point (one rotor diameter upstream at hub height,
`WindFarm.reference_points`) with the lidar's sample points through `lidarjax.io.monitor_points`
(OpenFOAM ``probes`` dictionary, zCFD ``turb_probe`` file, CSV).
"""

from __future__ import annotations

import csv
import io as _io
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._util import PathLike, file_error, import_optional, normalise_key, require_file
from ..scenes.farm import clip_thrust_curve, wind_farm

__all__ = ["Layout", "TurbineType", "FarmLayout", "read_layout", "read_turbine_type",
           "read_farm", "check_spacing"]

_SPEED_KEYS = ("speed", "windspeed", "speedms", "ws", "u")
_CT_KEYS = ("ct", "thrustcoefficient", "thrust")
_DIAMETER_KEYS = ("rotordiameter", "rotordiameterm", "diameter", "diameterm", "d")
_HUB_KEYS = ("hubheight", "hubheightm", "hh")


@dataclass(frozen=True)
class Layout:
    """One layout file: ``(i,)`` `names`, `easting`, `northing` (m), and its `path`."""

    path: Path
    names: tuple[str, ...]
    easting: np.ndarray
    northing: np.ndarray


@dataclass(frozen=True)
class TurbineType:
    """A turbine type: `diameter` and `hub_height` (m), thrust curve `speed` (m/s), `ct`."""

    path: Path
    name: str
    diameter: float
    hub_height: float
    speed: np.ndarray
    ct: np.ndarray


@dataclass(frozen=True)
class FarmLayout:
    """All turbines of one or more layout files, each with its type (``(i,)`` arrays)."""

    names: tuple[str, ...]
    easting: np.ndarray
    northing: np.ndarray
    diameter: np.ndarray
    hub_height: np.ndarray
    types: tuple[TurbineType, ...] = field(repr=False)
    type_index: np.ndarray = field(repr=False)

    @property
    def curves(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """One ``(speed, ct)`` curve per turbine (for `lidarjax.scenes.wind_farm`'s `ct`)."""
        return [(self.types[k].speed, self.types[k].ct) for k in self.type_index]

    def to_farm(self, **kwargs):
        """A `lidarjax.scenes.WindFarm` of these turbines; `kwargs` go to `wind_farm`
        (speed, direction, model, ...)."""

        return wind_farm(self.easting, self.northing, self.hub_height, self.diameter,
                         ct=self.curves, **kwargs)


def read_layout(path: PathLike) -> Layout:
    """Read a seed 004 layout file ``<name> <easting> <northing>`` (see module docs).

    Raises `FileNotFoundError`, or `ValueError` naming the file and line for a line without
    three fields, a non-numeric coordinate, a duplicate name or an empty file."""
    p = require_file(path, "layout file")
    names: list[str] = []
    coords: list[tuple[float, float]] = []
    seen: dict[str, int] = {}
    for number, raw in enumerate(p.read_text(encoding="utf-8-sig").splitlines(), start=1):
        text = raw.split("#", 1)[0].strip()
        if not text:
            continue
        parts = [s for s in re.split(r"[\s,;]+", text) if s]
        if len(parts) != 3:
            raise file_error(p, number, f"expected '<name> <easting> <northing>', found {raw.strip()!r}")
        name = parts[0]
        try:
            e, n = float(parts[1]), float(parts[2])
        except ValueError:
            raise file_error(p, number, f"turbine {name!r}: easting and northing must be numbers "
                                        f"(metres), found {parts[1]!r} {parts[2]!r}") from None
        if not (np.isfinite(e) and np.isfinite(n)):
            raise file_error(p, number, f"turbine {name!r}: coordinates must be finite")
        if name in seen:
            raise file_error(p, number, f"duplicate turbine name {name!r} (first on line {seen[name]})")
        seen[name] = number
        names.append(name)
        coords.append((e, n))
    if not names:
        raise file_error(p, None, "no turbines (expected lines '<name> <easting> <northing>')")
    c = np.array(coords, dtype=np.float64)
    return Layout(p, tuple(names), c[:, 0], c[:, 1])


def read_turbine_type(path: PathLike) -> TurbineType:
    """Read a turbine type: a CSV (see module docs: ``# rotor_diameter = ...``,
    ``# hub_height = ...`` header lines and ``speed,ct`` columns), or a YAML file
    (``.yaml``/``.yml``) in FLORIS's turbine-library layout (``hub_height``,
    ``rotor_diameter``, ``power_thrust_table: {wind_speed, thrust_coefficient}``, e.g.
    FLORIS's own ``nrel_5MW.yaml``) or windIO's plant turbine layout (``name``,
    ``hub_height``, ``rotor_diameter``, ``performance: {Ct_curve: {Ct_wind_speeds,
    Ct_values}}``). YAML needs PyYAML (extra ``farm``).

    A thrust curve that leaves ``[0, 1)`` (FLORIS's NREL 5 MW reaches 1.13 below cut-in) is
    clipped to ``[1e-4, 0.9999]`` as FLORIS clips it, with one warning naming the file.
    Raises `ValueError` naming the file (and line) for a missing diameter/hub height, missing
    thrust-curve columns or keys, non-numeric values or speeds not increasing."""
    p = require_file(path, "turbine type file")
    if p.suffix.lower() in (".yaml", ".yml"):
        return _read_turbine_yaml(p)
    meta: dict[str, str] = {}
    body: list[tuple[int, str]] = []
    for number, raw in enumerate(p.read_text(encoding="utf-8-sig").splitlines(), start=1):
        s = raw.strip()
        if not s:
            continue
        if s.startswith("#"):
            m = re.match(r"#\s*([^=:]+?)\s*[=:]\s*(.+?)\s*$", s)
            if m:
                meta[normalise_key(m.group(1))] = m.group(2).split()[0]
            continue
        body.append((number, s))

    def number_of(keys, what):
        for k in keys:
            if k in meta:
                try:
                    v = float(meta[k])
                except ValueError:
                    raise file_error(p, None, f"{what} must be a number of metres, found "
                                              f"{meta[k]!r}") from None
                if not (np.isfinite(v) and v > 0):
                    raise file_error(p, None, f"{what} must be positive metres, found {v:g}")
                return v
        raise file_error(p, None, f"missing '# {keys[0]} = <metres>' header line ({what})")

    diameter = number_of(_DIAMETER_KEYS, "rotor diameter")
    hub = number_of(_HUB_KEYS, "hub height")
    if not body:
        raise file_error(p, None, "missing thrust-curve columns 'speed,ct' (no table)")
    header_line, header = body[0]
    cols = [normalise_key(c) for c in next(csv.reader(_io.StringIO(header)))]
    found = {}
    for want, keys in (("speed", _SPEED_KEYS), ("ct", _CT_KEYS)):
        idx = [i for i, c in enumerate(cols) if c in keys]
        if not idx:
            raise file_error(p, header_line, f"missing thrust-curve column {want!r} (header "
                                             f"{header!r}; expected columns 'speed,ct')")
        found[want] = idx[0]
    rows = []
    for number, s in body[1:]:
        fields = next(csv.reader(_io.StringIO(s)))
        try:
            rows.append((float(fields[found["speed"]]), float(fields[found["ct"]])))
        except (ValueError, IndexError):
            raise file_error(p, number, f"expected numbers in columns 'speed' and 'ct', found "
                                        f"{s!r}") from None
    if len(rows) < 1:
        raise file_error(p, None, "the thrust curve has no rows")
    a = np.array(rows, dtype=np.float64)
    if not np.all(np.isfinite(a)):
        raise file_error(p, None, "the thrust curve contains NaN or inf")
    if np.any(np.diff(a[:, 0]) <= 0):
        k = int(np.argmax(np.diff(a[:, 0]) <= 0))
        raise file_error(p, body[k + 2][0], "thrust-curve speeds must be strictly increasing")
    ct = clip_thrust_curve(a[:, 1], str(p))
    if hub < 0.5 * diameter:
        raise file_error(p, None, f"hub height {hub:g} m is below the rotor radius {0.5 * diameter:g} m")
    return TurbineType(p, p.stem, diameter, hub, a[:, 0], ct)


def _read_turbine_yaml(p: Path) -> TurbineType:
    """A FLORIS turbine-library or windIO plant turbine YAML (see `read_turbine_type`)."""
    yaml = import_optional("yaml", "farm", f"Reading the turbine YAML {p}")
    try:
        data = yaml.safe_load(p.read_text(encoding="utf-8-sig"))
    except yaml.YAMLError as err:
        raise file_error(p, None, f"not valid YAML ({str(err).splitlines()[0]})") from None
    if not isinstance(data, dict):
        raise file_error(p, None, "expected a mapping with hub_height, rotor_diameter and a "
                                  "thrust curve (FLORIS or windIO turbine)")
    if isinstance(data.get("power_thrust_table"), dict):  # FLORIS turbine library
        table, kind = data["power_thrust_table"], "FLORIS"
        speed_key, ct_key, name = "wind_speed", "thrust_coefficient", data.get("turbine_type")
    elif isinstance(data.get("performance"), dict) and isinstance(
            data["performance"].get("Ct_curve"), dict):  # windIO plant turbine
        table, kind = data["performance"]["Ct_curve"], "windIO"
        speed_key, ct_key, name = "Ct_wind_speeds", "Ct_values", data.get("name")
    else:
        raise file_error(p, None, "no thrust curve: expected FLORIS's power_thrust_table "
                                  "{wind_speed, thrust_coefficient} or windIO's performance: "
                                  "{Ct_curve: {Ct_wind_speeds, Ct_values}}")

    def number(key):
        try:
            v = float(data[key])
        except KeyError:
            raise file_error(p, None, f"{kind} turbine without {key!r} (metres)") from None
        except (TypeError, ValueError):
            raise file_error(p, None, f"{key} must be a number of metres, found "
                                      f"{data[key]!r}") from None
        if not (np.isfinite(v) and v > 0):
            raise file_error(p, None, f"{key} must be positive metres, found {v:g}")
        return v

    diameter, hub = number("rotor_diameter"), number("hub_height")
    try:
        speed = np.asarray(table[speed_key], np.float64)
        ct = np.asarray(table[ct_key], np.float64)
    except KeyError as err:
        raise file_error(p, None, f"{kind} thrust curve without {err.args[0]!r}") from None
    except (TypeError, ValueError):
        raise file_error(p, None, f"{kind} thrust curve: {speed_key} and {ct_key} must be "
                                  "lists of numbers") from None
    if speed.ndim != 1 or speed.shape != ct.shape or speed.size < 1:
        raise file_error(p, None, f"{kind} thrust curve: {speed_key} and {ct_key} must be lists "
                                  f"of one length, found {speed.shape} and {ct.shape}")
    if not np.all(np.isfinite(speed)):
        raise file_error(p, None, f"{kind} thrust curve: {speed_key} contains NaN or inf")
    if np.any(np.diff(speed) <= 0):
        raise file_error(p, None, "thrust-curve speeds must be strictly increasing")
    try:
        ct = clip_thrust_curve(ct, str(p))
    except ValueError as err:
        raise file_error(p, None, str(err).split(": ", 1)[-1]) from None
    if hub < 0.5 * diameter:
        raise file_error(p, None, f"hub height {hub:g} m is below the rotor radius {0.5 * diameter:g} m")
    return TurbineType(p, str(name) if name else p.stem, diameter, hub, speed, ct)


def check_spacing(names, easting, northing, diameter) -> None:
    """Raise `ValueError` when two turbines stand closer than one rotor diameter (the larger
    of the pair), naming both."""
    e, n, d = (np.asarray(a, np.float64) for a in (easting, northing, diameter))
    for i in range(e.size - 1):
        dist = np.hypot(e[i + 1:] - e[i], n[i + 1:] - n[i])
        limit = np.maximum(d[i + 1:], d[i])
        bad = np.flatnonzero(dist < limit)
        if bad.size:
            j = i + 1 + int(bad[0])
            raise ValueError(f"turbines {names[i]} and {names[j]} are {dist[bad[0]]:.1f} m apart, "
                             f"closer than one rotor diameter ({limit[bad[0]]:g} m)")


def read_farm(layouts, types) -> FarmLayout:
    """Read layout files, each paired with a turbine type file (seed 004's
    ``turbine_files=[[xy_file, type_file], ...]``).

    **Arguments:** `layouts`: one or more layout paths; `types`: one type path for all of
    them, or one per layout.

    Raises `ValueError` for mismatched counts, names repeated across files, or turbines
    closer than one rotor diameter (`check_spacing`)."""
    layouts = [layouts] if isinstance(layouts, str | Path) else list(layouts)
    types = [types] if isinstance(types, str | Path) else list(types)
    if not layouts:
        raise ValueError("read_farm: give at least one layout file")
    if len(types) == 1:
        types = types * len(layouts)
    if len(types) != len(layouts):
        raise ValueError(f"read_farm: {len(layouts)} layout files need one turbine type each or "
                         f"one for all; got {len(types)}")
    read_types: dict[str, TurbineType] = {}
    kinds = []
    for t in types:
        key = str(Path(t).resolve()) if Path(t).exists() else str(t)
        if key not in read_types:
            read_types[key] = read_turbine_type(t)
        kinds.append(key)
    keys = list(read_types)
    names: list[str] = []
    where: dict[str, str] = {}
    e, n, tix = [], [], []
    for path, kind in zip(layouts, kinds, strict=True):
        lay = read_layout(path)
        for name, x, y in zip(lay.names, lay.easting, lay.northing, strict=True):
            if name in where:
                raise ValueError(f"{lay.path}: duplicate turbine name {name!r} (also in {where[name]})")
            where[name] = str(lay.path)
            names.append(name)
            e.append(x)
            n.append(y)
            tix.append(keys.index(kind))
    tt = tuple(read_types[k] for k in keys)
    tix_a = np.array(tix)
    diam = np.array([tt[k].diameter for k in tix_a])
    hub = np.array([tt[k].hub_height for k in tix_a])
    check_spacing(names, e, n, diam)
    return FarmLayout(tuple(names), np.array(e), np.array(n), diam, hub, tt, tix_a)
