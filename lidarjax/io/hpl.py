"""Halo Photonics StreamLine ``.hpl`` files (stare, VAD, PPI, RHI and user scans).

The file is text: a header of ``key:<TAB>value`` lines up to a line starting with ``****``
(which may carry ``Instrument spectral width = x``), then per ray one line ``decimal_time
azimuth elevation [pitch roll]`` (hours since midnight of the start date, degrees; older
systems write the first three only) followed by one line per gate ``gate doppler intensity
beta [spectral_width]`` (gate index from 0; Doppler m/s, positive away from the lidar;
intensity SNR + 1; attenuated backscatter m-1 sr-1; older headers have no spectral width).
Gate centres follow the header's "Range (or Altitude) of measurement (center of gate)"
line: ``(range gate + 0.5) * Gate length`` (contiguous gates, the usual one and the default
when the line is absent) or, with overlapping gates, ``Gate length / 2 + (range gate x d)``,
gates ``d`` metres apart (one sampling point, 3 m, in the committed RHI: 18 m gates every
3 m); a formula in neither form is refused rather than guessed.

**Rays and scans.** The rays of the file are the rays it holds. The header's ``No. of rays
in file`` (``No. of waypoints in file`` for user scans) counts the rays of *one scan*: a stare
or a repeated VAD written over an hour holds many scans (the stares of the real Eriswil and
Warsaw files: header 1, 2 rays held). `HaloScan.rays_per_scan` keeps it; the rays are
grouped into scans of that many (`HaloScan.scan`, `HaloScan.per_scan`). Where the rays held
are not a whole number of scans (the real Soverato VAD: 6 per scan, 2 held) a one-line
warning says so and every ray is kept, the last scan incomplete.

**Times.** Ray times are the decimal hours after midnight of the header's start date, made
continuous: where the hours drop by more than 12 h (midnight crossed) a day is added, and a
first ray more than 12 h from the header's start time (a file started just after midnight
whose first ray was written just before) is moved by a day. `HaloScan.decimal_hours` keeps
the numbers as written.

**Truncated files.** A file cut while it was written (its last ray short of gates, or its
last line cut: fewer numbers, a number cut off, or, without a final newline, a last number
with other decimals than the line before) keeps its complete rays, with a one-line warning
naming the file and line. A file malformed beyond that (a header field missing or
unreadable, a ray or gate line that is not numbers before the end, gates out of order, a
ray short of gates followed by more rays, no complete ray) is refused with one line naming
the file and line.

`HaloScan.radial_velocity` applies the intensity threshold: gates with intensity (SNR + 1)
below it are NaN (default `INTENSITY_THRESHOLD` = 1.015, about -18 dB SNR, of the order used
for StreamLine data, e.g. Paeschke et al. 2015, Atmos. Meas. Tech. 8, 2251-2266; choose your
own). `HaloScan.pattern` gives the `lidarjax.scanning.ScanPattern` of the file's layout
(every ray of every scan at its own time) for a simulation to compare with.
"""

from __future__ import annotations

import dataclasses
import datetime as _dt
import re
import warnings

import numpy as np

from .._util import PathLike, file_error, require_file
from ..scanning import ScanPattern
from ._common import ends_with_line_end, field_cut, read_text

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
    """A Halo ``.hpl`` file (dimensions ``r`` rays held, ``g`` gates; numpy arrays).

    Header: `path`, `system_id`, `n_gates`, `gate_length` (m), `gate_points`,
    `pulses_per_ray`, `rays_per_scan` (the header's ``No. of rays in file`` or ``No. of
    waypoints in file``: rays of one scan; None when absent), `scan_type`, `focus_range`,
    `start_time` (``datetime64[us]``), `resolution` (m/s), `instrument_spectral_width` (m/s,
    from the ``****`` line, or None), `header` (all fields, as text).
    Per ray: `n_rays` (``r``, the rays the file holds), `scan` ``(r,)`` the scan each ray
    belongs to (``ray // rays_per_scan``, from 0), `time` (``datetime64[us]``, continuous
    across midnight), `decimal_hours` (as written), `azimuth`, `elevation`, `pitch`, `roll`
    (degrees; `pitch` and `roll` None when the ray lines hold three numbers). Per gate:
    `ranges` ``(g,)`` gate centres (m, from the header's range formula; `gate_spacing` m
    apart, `gate_length` for contiguous gates, less when they overlap); `doppler`,
    `intensity`, `beta` ``(r, g)``; `spectral_width` ``(r, g)`` or None.
    """

    path: str
    header: dict
    system_id: str
    n_gates: int
    gate_length: float
    gate_points: int | None
    pulses_per_ray: int | None
    n_rays: int
    rays_per_scan: int | None
    scan_type: str
    focus_range: float | None
    start_time: np.datetime64
    resolution: float | None
    instrument_spectral_width: float | None
    scan: np.ndarray
    time: np.ndarray
    decimal_hours: np.ndarray
    azimuth: np.ndarray
    elevation: np.ndarray
    pitch: np.ndarray | None
    roll: np.ndarray | None
    ranges: np.ndarray
    gate_spacing: float
    doppler: np.ndarray
    intensity: np.ndarray
    beta: np.ndarray
    spectral_width: np.ndarray | None

    @property
    def n_scans(self) -> int:
        """Scans the file holds (the last one incomplete where the rays are not a whole
        number of scans)."""
        return int(self.scan[-1]) + 1

    @property
    def complete_scans(self) -> int:
        """Scans of `rays_per_scan` rays the file holds in full (all rays are one scan when
        the header gives no count)."""
        return self.n_rays // self.rays_per_scan if self.rays_per_scan else 1

    def per_scan(self, values: np.ndarray) -> np.ndarray:
        """Per-ray `values` ``(r, ...)`` as ``(s, m, ...)``: the `complete_scans` ``s`` of
        `rays_per_scan` ``m`` rays each (an incomplete last scan left out; select it with
        `rays`). E.g. ``vad_fit(s.per_scan(s.radial_velocity()), s.per_scan(s.azimuth),
        s.per_scan(s.elevation), s.ranges)`` fits every scan of a repeated VAD."""
        values = np.asarray(values)
        if values.shape[:1] != (self.n_rays,):
            raise ValueError(f"per_scan: values must have one row per ray ({self.n_rays},), got "
                             f"shape {values.shape}")
        m = self.rays_per_scan or self.n_rays
        s = self.complete_scans
        return values[:s * m].reshape(s, m, *values.shape[1:])

    def rays(self, which) -> HaloScan:
        """The file with only the rays `which` (an index, slice or boolean mask over the
        rays, e.g. ``s.scan == 3`` for the fourth scan); header fields kept."""
        idx = np.arange(self.n_rays)[which]
        idx = np.atleast_1d(idx)
        if idx.size == 0:
            raise ValueError(f"{self.path}: the selection holds no ray")
        per_ray = {name: (None if getattr(self, name) is None else getattr(self, name)[idx])
                   for name in ("scan", "time", "decimal_hours", "azimuth", "elevation", "pitch",
                                "roll", "doppler", "intensity", "beta", "spectral_width")}
        return dataclasses.replace(self, n_rays=int(idx.size), **per_ray)

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
        """The file's layout as a `ScanPattern`: every ray the file holds (all its scans, in
        the order written), step-and-stare at the file's azimuths and elevations and its
        gate centres, each ray's accumulation (default `accumulation()`) ending at the ray's
        own time. Times are seconds from the start of the first ray's accumulation,
        `reference_time` (the header's start time can be later than the first ray's time:
        it is in every real file read here); the period is the last ray's end. One scan
        only: ``s.rays(s.scan == k).pattern()``. Pitch and roll are the instrument's tilt:
        give them to the `lidarjax.Mount`."""
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
_RAY_LINE = "ray line (time, azimuth, elevation[, pitch, roll])"
_GATE_LINE = "gate line (gate, doppler, intensity, beta[, width])"


class _Cut(Exception):
    """A problem on the last line of the file or past its end: the file was truncated."""

    def __init__(self, line: int, message: str):
        super().__init__(message)
        self.line, self.message = line, message


def _numbers(path, line_no, text, counts, what):
    fields = text.split()
    if len(fields) not in counts or not all(_NUMBER.match(f) for f in fields):
        want = " or ".join(str(c) for c in counts)
        raise file_error(path, line_no, f"expected a {what} of {want} numbers, found {text.strip()!r}")
    return [float(f) for f in fields]


def _read_ray(p, lines, i, n_gates, ray_counts, last, newline_end):
    """Ray line `i` (0-based) and its gate lines: ``(ray, gates (g, 4), width count)``.
    Raises `_Cut` where the problem is the file's end, a one-line ValueError otherwise."""

    def fail(j, message):  # j: 0-based line of the problem
        if j >= last:  # the last line, or past it: name the file's last line
            raise _Cut(min(j, last) + 1, message)
        raise file_error(p, j + 1, message)

    try:
        ray = _numbers(p, i + 1, lines[i], ray_counts, _RAY_LINE)
    except ValueError as err:
        fail(i, str(err).split(": ", 2)[-1])
    block = lines[i + 1:i + 1 + n_gates]
    rows = [line.split() for line in block]
    if len(rows) == n_gates and len({len(r) for r in rows}) == 1 and len(rows[0]) in (4, 5):
        try:  # fast path: every gate line numbers of one width, gates 0..g-1
            data = np.array(rows, dtype=np.float64)
        except ValueError:
            data = None
        if (data is not None and np.isfinite(data).all()
                and np.array_equal(data[:, 0], np.arange(n_gates))
                and all(_NUMBER.match(f) for f in rows[-1])):
            _check_last_line(p, lines, i + n_gates, last, newline_end, rows, fail)
            return ray, data[:, 1:], data.shape[1]
    out = []
    for k in range(n_gates):
        j = i + 1 + k
        if j >= len(lines) or not lines[j].strip():
            fail(j, f"ray {lines[i].split()[0]} ends after {k} of {n_gates} gates")
        try:
            vals = _numbers(p, j + 1, lines[j], (4, 5), _GATE_LINE)
        except ValueError as err:
            fail(j, str(err).split(": ", 2)[-1])
        if int(vals[0]) != k or vals[0] != int(vals[0]):
            fail(j, f"gate {vals[0]:g} where gate {k} was expected")
        out.append(vals)
    widths = {len(v) for v in out}
    if len(widths) > 1:
        j = i + 1 + next(k for k, v in enumerate(out) if len(v) != len(out[0]))
        raise file_error(p, j + 1, f"gate line of {len(out[j - i - 1])} numbers among gate lines of "
                         f"{len(out[0])}")
    _check_last_line(p, lines, i + n_gates, last, newline_end, [line.split() for line in block], fail)
    return ray, np.asarray(out)[:, 1:], len(out[0])


def _check_last_line(p, lines, j, last, newline_end, rows, fail):
    """Without a final newline, the file's last line is cut when its last number has other
    decimals than the same number on the line before (fixed Fortran formats: `field_cut`)."""
    if j != last or newline_end or len(rows) < 2:
        return
    why = field_cut(rows[-1][-1], [rows[-2][-1]])
    if why is not None:
        fail(j, f"last line {lines[j].strip()!r} has its last number cut (no final newline: {why})")


def read_hpl(path: PathLike) -> HaloScan:
    """Read a Halo StreamLine ``.hpl`` file (module docs).

    **Arguments:**

    - `path`: the ``.hpl`` file.

    **Returns:** a `HaloScan` of every complete ray the file holds. Raises
    `FileNotFoundError` for a missing file and a one-line `ValueError` naming the file and
    line for a malformed one; warns (`UserWarning`, one line naming the file) for a
    truncated file and for rays that are not a whole number of the header's scans.
    """
    p = require_file(path, "Halo .hpl file")
    text = read_text(p)
    lines = text.splitlines()
    header, end = _read_header(p, lines)
    n_gates = _int_field(p, lines, header, "number of gates")
    gate_length = _float_field(p, lines, header, "range gate length (m)")
    per_scan_key = next((k for k in ("no. of rays in file", "no. of waypoints in file") if k in header), None)
    rays_per_scan = _int_field(p, lines, header, per_scan_key) if per_scan_key else None
    start = _start_time(p, lines, header)
    first, spacing = _gate_layout(p, lines[:end], gate_length)
    # a line end after the last line (blanks may follow it): the line was written whole
    newline_end = ends_with_line_end(text)
    rays, gates, cut = _read_rays(p, lines, end, n_gates, newline_end)
    n = len(rays)
    _warn_incomplete(p, n, rays_per_scan, per_scan_key, cut)
    ray = np.asarray(rays)
    data = np.stack(gates)  # (r, g, 3 or 4)
    written = ray[:, 0].copy()
    return HaloScan(
        path=str(p), header=header, system_id=header.get("system id", ""), n_gates=n_gates,
        gate_length=gate_length, gate_points=_opt_int(header.get("gate length (pts)")),
        pulses_per_ray=_opt_int(header.get("pulses/ray")), n_rays=n, rays_per_scan=rays_per_scan,
        scan_type=header["scan type"], focus_range=_opt_float(header.get("focus range")),
        start_time=np.datetime64(start, "us"), resolution=_opt_float(header.get("resolution (m/s)")),
        instrument_spectral_width=_opt_float(header.get("instrument spectral width")),
        scan=np.arange(n) // (rays_per_scan or n), time=_ray_times(written, start),
        decimal_hours=written, azimuth=ray[:, 1], elevation=ray[:, 2],
        pitch=ray[:, 3] if ray.shape[1] == 5 else None, roll=ray[:, 4] if ray.shape[1] == 5 else None,
        ranges=first + spacing * np.arange(n_gates), gate_spacing=spacing,
        doppler=data[..., 0], intensity=data[..., 1], beta=data[..., 2],
        spectral_width=data[..., 3] if data.shape[-1] == 4 else None)


def _read_header(p, lines) -> tuple[dict[str, str], int]:
    """The header's ``key: value`` fields (keys lower case) and the 0-based line of its
    closing ``****`` (whose ``key = value``, the instrument spectral width, is kept too)."""
    header: dict[str, str] = {}
    end = None
    for i, line in enumerate(lines):
        if line.startswith("****"):
            end = i
            rest = line.lstrip("*").strip()
            if "=" in rest:
                key, _, value = rest.partition("=")
                header[key.strip().lower()] = value.strip()
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
    return header, end


def _start_time(p, lines, header) -> _dt.datetime:
    """The header's start time (``YYYYMMDD HH:MM:SS[.ss]``)."""
    try:
        text = header["start time"]
        return _dt.datetime.strptime(text, "%Y%m%d %H:%M:%S.%f" if "." in text else "%Y%m%d %H:%M:%S")
    except ValueError:
        raise file_error(p, _line_of(lines, "Start time"), f"start time {header['start time']!r} is "
                         f"not 'YYYYMMDD HH:MM:SS.ss'") from None


def _read_rays(p, lines, end, n_gates, newline_end) -> tuple[list, list, _Cut | None]:
    """Every complete ray after the header line `end`: ``(ray lines, gate blocks, the
    truncation met or None)``."""
    last = max((i for i, line in enumerate(lines) if line.strip()), default=-1)
    rays, gates = [], []
    ray_counts, width, cut = (3, 5), None, None
    i = end + 1
    while i <= last:
        if not lines[i].strip():
            i += 1
            continue
        try:
            ray, block, w = _read_ray(p, lines, i, n_gates, ray_counts, last, newline_end)
        except _Cut as err:
            cut = err
            if not rays:
                raise file_error(p, cut.line, f"{cut.message}: no complete ray") from None
            break
        if width is not None and w != width:
            raise file_error(p, i + 2, f"gate lines of {w} numbers after rays with gate lines of "
                             f"{width}")
        width, ray_counts = w, (len(ray),)
        rays.append(ray)
        gates.append(block)
        i += 1 + n_gates
    if not rays:
        raise file_error(p, end + 2, "no ray follows the header")
    return rays, gates, cut


def _warn_incomplete(p, n, rays_per_scan, per_scan_key, cut) -> None:
    """One warning for a truncated file or rays that are not a whole number of scans."""
    partial = (f"the last scan has {n % rays_per_scan} of the header's {rays_per_scan} rays per "
               f"scan" if rays_per_scan and n % rays_per_scan else None)
    if cut is not None:
        warnings.warn(f"{p}, line {cut.line}: truncated file ({cut.message}); kept its {n} "
                      f"complete rays" + (f" ({partial})" if partial else ""), UserWarning,
                      stacklevel=3)
    elif partial:
        warnings.warn(f"{p}: the header's {per_scan_key!r} gives {rays_per_scan} rays per scan and "
                      f"the file holds {n} rays, not a whole number of scans: all {n} kept, "
                      f"{partial}", UserWarning, stacklevel=3)


def _ray_times(written: np.ndarray, start: _dt.datetime) -> np.ndarray:
    """Ray times (`datetime64[us]`) from the decimal hours as written, made continuous past
    midnight, the first ray within 12 h of the header's start time."""
    hours = written.copy()
    for k in range(1, hours.size):  # continue past midnight
        while hours[k - 1] - hours[k] > 12.0:
            hours[k:] += 24.0
    of_day = (start - start.replace(hour=0, minute=0, second=0, microsecond=0)).total_seconds() / 3600
    hours += 24.0 * np.round((of_day - hours[0]) / 24.0)  # the first ray within 12 h of the start
    day = np.datetime64(start.date(), "us")
    return day + np.round(hours * 3600e6).astype("timedelta64[us]")


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
