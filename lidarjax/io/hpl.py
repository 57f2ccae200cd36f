"""Halo Photonics StreamLine ``.hpl`` files (stare, VAD, PPI, RHI and user scans).

The file is text: a header of ``key:<TAB>value`` lines up to a line starting with ``****``,
then per ray one line ``decimal_time azimuth elevation pitch roll`` (hours since midnight of
the start date, degrees) followed by one line per gate ``gate doppler intensity beta
[spectral_width]`` (gate index from 0; Doppler m/s, positive away from the lidar; intensity
SNR + 1; attenuated backscatter m-1 sr-1). Gate centres follow the header's "Range (or
Altitude) of measurement (center of gate)" line: ``(range gate + 0.5) * Gate length``
(contiguous gates, the usual one and the default when the line is absent) or, with
overlapping gates, ``Gate length / 2 + (range gate x d)``, gates ``d`` metres apart (one
sampling point, 3 m, in the committed RHI: 18 m gates every 3 m); a formula in neither form
is refused rather than guessed. Decimal hours that wrap past midnight are continued
(``+ 24 h`` when a ray's time drops by more than 12 h).

`read_hpl` refuses a malformed file with one line naming the file and line (a header field
missing or unreadable, a ray line or gate line that is not numbers, gates out of order, a
ray with fewer gates than the header says, more or fewer rays than the header says).

`HaloScan.radial_velocity` applies the intensity threshold: gates with intensity (SNR + 1)
below it are NaN (default `INTENSITY_THRESHOLD` = 1.015, about -18 dB SNR, of the order used
for StreamLine data, e.g. Paeschke et al. 2015, Atmos. Meas. Tech. 8, 2251-2266; choose your
own). `HaloScan.pattern` gives the `lidarjax.scanning.ScanPattern` of the file's layout
(same rays, ranges and times) for a simulation to compare with.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import re

import numpy as np

from .._util import PathLike, file_error, require_file
from ..scanning import ScanPattern
from ._common import read_text

__all__ = ["HaloScan", "read_hpl", "INTENSITY_THRESHOLD", "HALO_PRF"]

#: Default intensity (SNR + 1) below which `HaloScan.radial_velocity` gives NaN.
INTENSITY_THRESHOLD = 1.015
#: Pulse repetition frequency of a StreamLine, Hz (public figure, 15 kHz; sets the
#: accumulation time ``pulses_per_ray / HALO_PRF`` when the file does not state one).
HALO_PRF = 15_000.0

_REQUIRED = {
    "number of gates": "n_gates",
    "range gate length (m)": "gate_length",
    "scan type": "scan_type",
    "start time": "start_time",
}


@dataclasses.dataclass(frozen=True)
class HaloScan:
    """A Halo ``.hpl`` file (dimensions ``r`` rays, ``g`` gates; numpy arrays).

    Header: `path`, `system_id`, `n_gates`, `gate_length` (m), `gate_points`,
    `pulses_per_ray`, `n_rays`, `scan_type`, `focus_range`, `start_time`
    (``datetime64[us]``), `resolution` (m/s), `header` (all fields, as text).
    Per ray: `time` (``datetime64[us]``), `decimal_hours`, `azimuth`, `elevation`, `pitch`,
    `roll` (degrees). Per gate: `ranges` ``(g,)`` gate centres (m, from the header's range
    formula; `gate_spacing` m apart, `gate_length` for contiguous gates, less when they
    overlap); `doppler`, `intensity`, `beta` ``(r, g)``; `spectral_width` ``(r, g)`` or None.
    """

    path: str
    header: dict
    system_id: str
    n_gates: int
    gate_length: float
    gate_points: int | None
    pulses_per_ray: int | None
    n_rays: int
    scan_type: str
    focus_range: float | None
    start_time: np.datetime64
    resolution: float | None
    time: np.ndarray
    decimal_hours: np.ndarray
    azimuth: np.ndarray
    elevation: np.ndarray
    pitch: np.ndarray
    roll: np.ndarray
    ranges: np.ndarray
    gate_spacing: float
    doppler: np.ndarray
    intensity: np.ndarray
    beta: np.ndarray
    spectral_width: np.ndarray | None

    def radial_velocity(self, threshold: float = INTENSITY_THRESHOLD) -> np.ndarray:
        """Doppler velocity ``(r, g)`` (m/s, positive away), NaN where the intensity (SNR +
        1) is below `threshold`."""
        return np.where(self.intensity >= threshold, self.doppler, np.nan)

    def seconds(self) -> np.ndarray:
        """Ray times in seconds from `start_time` ``(r,)``."""
        return (self.time - self.start_time) / np.timedelta64(1, "us") * 1e-6

    def accumulation(self) -> float:
        """Seconds per ray: ``pulses_per_ray / HALO_PRF`` (1 s when the header has none)."""
        return 1.0 if not self.pulses_per_ray else self.pulses_per_ray / HALO_PRF

    def pattern(self, *, accumulation: float | None = None) -> ScanPattern:
        """The file's layout as a `ScanPattern`: step-and-stare rays at the file's azimuths
        and elevations and its gate centres, each ray's accumulation (default
        `accumulation()`) ending at the ray's time. Times are seconds from the start of the
        first ray's accumulation, `reference_time` (the header's start time can be later
        than the first ray's time: it is in both committed files). Pitch and roll are the
        instrument's tilt: give them to the `lidarjax.Mount`."""
        acc = self.accumulation() if accumulation is None else float(accumulation)
        t_end = (self.time - self.time[0]) / np.timedelta64(1, "us") * 1e-6 + acc
        start = np.maximum.accumulate(t_end - acc)
        return ScanPattern(self.azimuth, self.elevation, self.ranges, ray_start=start,
                           accumulation=acc, period=float(start[-1] + acc),
                           kind=_kind(self.scan_type))

    def reference_time(self, *, accumulation: float | None = None) -> np.datetime64:
        """Start of the first ray's accumulation: the origin of `pattern`'s times."""
        acc = self.accumulation() if accumulation is None else float(accumulation)
        return self.time[0] - np.timedelta64(int(round(acc * 1e6)), "us")


def _kind(scan_type: str) -> str:
    # whole words: "RHI - overlapping" holds "ppi" inside "overlapping"
    words = re.findall(r"[a-z]+", scan_type.lower())
    for key in ("stare", "vad", "ppi", "rhi"):
        if key in words:
            return key
    return "custom"


_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")


def _numbers(path, line_no, text, count, what):
    fields = text.split()
    if len(fields) < count[0] or len(fields) > count[1] or not all(_NUMBER.match(f) for f in fields):
        want = f"{count[0]}" if count[0] == count[1] else f"{count[0]} or {count[1]}"
        raise file_error(path, line_no, f"expected a {what} of {want} numbers, found {text.strip()!r}")
    return [float(f) for f in fields]


def read_hpl(path: PathLike) -> HaloScan:
    """Read a Halo StreamLine ``.hpl`` file (module docs). Raises `FileNotFoundError` for a
    missing file and a one-line `ValueError` naming the file and line for a malformed one."""
    p = require_file(path, "Halo .hpl file")
    lines = read_text(p).splitlines()
    header: dict[str, str] = {}
    end = None
    for i, line in enumerate(lines):
        if line.startswith("****"):
            end = i
            break
        if ":" in line and not line.startswith(("Data line", "Range of measurement",
                                                "Altitude of measurement")):
            key, _, value = line.partition(":")
            header[key.strip().lower()] = value.strip()
    if end is None:
        raise file_error(p, None, "no '****' line ends the header: not a Halo .hpl file")
    for key in _REQUIRED:
        if key not in header:
            raise file_error(p, None, f"header field {key!r} is missing: not a Halo .hpl file")
    n_gates = _int_field(p, lines, header, "number of gates")
    gate_length = _float_field(p, lines, header, "range gate length (m)")
    n_rays_key = next((k for k in ("no. of rays in file", "no. of waypoints in file") if k in header), None)
    n_rays = _int_field(p, lines, header, n_rays_key) if n_rays_key else None
    try:
        start = _dt.datetime.strptime(header["start time"], "%Y%m%d %H:%M:%S.%f")
    except ValueError:
        raise file_error(p, _line_of(lines, "Start time"), f"start time {header['start time']!r} is "
                         f"not 'YYYYMMDD HH:MM:SS.ss'") from None
    first, spacing = _gate_layout(p, lines[:end], gate_length)
    rays, gates = [], []
    i = end + 1
    while i < len(lines):
        if not lines[i].strip():
            i += 1
            continue
        ray = _numbers(p, i + 1, lines[i], (5, 5), "ray line (time, azimuth, elevation, pitch, roll)")
        block = []
        for k in range(n_gates):
            j = i + 1 + k
            if j >= len(lines) or not lines[j].strip():
                raise file_error(p, j + 1, f"ray {len(rays)} ends after {k} of {n_gates} gates")
            vals = _numbers(p, j + 1, lines[j], (4, 5), "gate line (gate, doppler, intensity, beta[, width])")
            if int(vals[0]) != k:
                raise file_error(p, j + 1, f"gate {int(vals[0])} where gate {k} was expected")
            block.append(vals[1:] + [np.nan] * (5 - len(vals)))
        rays.append(ray)
        gates.append(block)
        i += 1 + n_gates
    if not rays:
        raise file_error(p, end + 2, "no ray follows the header")
    if n_rays is not None and len(rays) != n_rays:
        raise file_error(p, len(lines), f"the header says {n_rays} rays, the file holds {len(rays)}")
    ray = np.asarray(rays)
    data = np.asarray(gates)  # (r, g, 4)
    hours = ray[:, 0].copy()
    for k in range(1, hours.size):  # continue past midnight
        while hours[k - 1] - hours[k] > 12.0:
            hours[k:] += 24.0
    day = np.datetime64(start.date(), "us")
    time = day + np.round(hours * 3600e6).astype("timedelta64[us]")
    width = data[..., 3] if np.any(np.isfinite(data[..., 3])) else None
    return HaloScan(
        path=str(p), header=header, system_id=header.get("system id", ""), n_gates=n_gates,
        gate_length=gate_length, gate_points=_opt_int(header.get("gate length (pts)")),
        pulses_per_ray=_opt_int(header.get("pulses/ray")), n_rays=len(rays),
        scan_type=header["scan type"], focus_range=_opt_float(header.get("focus range")),
        start_time=np.datetime64(start, "us"), resolution=_opt_float(header.get("resolution (m/s)")),
        time=time, decimal_hours=hours, azimuth=ray[:, 1], elevation=ray[:, 2], pitch=ray[:, 3],
        roll=ray[:, 4], ranges=first + spacing * np.arange(n_gates), gate_spacing=spacing,
        doppler=data[..., 0],
        intensity=data[..., 1], beta=data[..., 2], spectral_width=width)


_CONTIGUOUS = "(rangegate+0.5)*gatelength"
_OVERLAPPING = re.compile(r"^gatelength/2\+\(rangegate[x*]([0-9]*\.?[0-9]+)\)$")


def _gate_layout(p, header_lines, gate_length):
    """(first gate centre, spacing) in m from the header's "(center of gate)" formula."""
    for i, line in enumerate(header_lines):
        if "center of gate" not in line.lower() or "=" not in line:
            continue
        formula = "".join(line.split("=", 1)[1].split()).lower()
        if formula == _CONTIGUOUS:
            return 0.5 * gate_length, gate_length
        match = _OVERLAPPING.match(formula)
        if match and float(match.group(1)) > 0:
            return 0.5 * gate_length, float(match.group(1))
        raise file_error(p, i + 1, f"gate-centre formula {line.split('=', 1)[1].strip()!r} is "
                         "neither '(range gate + 0.5) * Gate length' nor 'Gate length / 2 + "
                         "(range gate x d)'")
    return 0.5 * gate_length, gate_length


def _line_of(lines, prefix):
    return next((i + 1 for i, line in enumerate(lines) if line.startswith(prefix)), None)


def _int_field(p, lines, header, key):
    text = header[key]
    try:
        value = int(text)
    except ValueError:
        value = -1
    if value < 1:
        raise file_error(p, _line_of(lines, key.split()[0].capitalize()),
                         f"header field {key!r} must be a positive integer, found {text!r}")
    return value


def _float_field(p, lines, header, key):
    text = header[key]
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0:
        raise file_error(p, _line_of(lines, "Range gate"),
                         f"header field {key!r} must be a positive number, found {text!r}")
    return value


def _opt_int(text):
    try:
        return int(text)
    except (TypeError, ValueError):
        return None


def _opt_float(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return None
