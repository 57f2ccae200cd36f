"""Correcting real lidar records with a response table, end to end (files in, files out).

`load_records` reads a Windcube ``.sta``/``.stdsta`` (10-minute statistics), ``.rtd``
(real-time line of sight, averaged to 10-minute beam means) or ZephIR ``.csv`` file into one
`RecordSet`; `check_instrument` compares the table's metadata with the record's header;
`correct_records` inverts every record and height with the table (streamed in chunks of one
compiled shape), and `write_corrected_csv` / `write_corrected_netcdf` write the result.

## Flags

Two bit masks per record and height. `CorrectedRecords.flags` holds the
`lidarjax.InverseFlag` bits of the inversion; `CorrectedRecords.record_flags` the
`RecordFlag` bits the reader found in the file (corrupt row, low availability, impossible
value, below the CNR threshold, partial interval, duplicate time, high CNR; see
`lidarjax.RecordFlag`). A record the file could not give is NaN with its reason,
never dropped and never reinterpreted (a negative reported speed is not turned into a
positive one from the opposite direction).

## Uncertainty of reported (``.sta``, ZephIR) records

A reported 10-minute record is the mean of the instrument's per-scan reconstructions. When
no `noise` is given, its noise level is the standard error of that mean, from the record's
own dispersion and availability (`reported_noise`), along and across the wind:

    n_eff       = availability * period / scan_period
    noise_along = sigma_u / sqrt(n_eff)
    noise_cross = sigma_v / sqrt(n_eff)

with ``sigma_u`` the speed dispersion (m/s, the file's ``Wind Speed Dispersion``; ZephIR:
``TI * speed`` when exported), ``sigma_v = speed * direction dispersion (rad)`` when the file
has one, else ``0.8 * sigma_u`` (the IEC 61400-1 ratio of lateral to longitudinal turbulence),
``availability`` in [0, 1] (1 when the file has no such column), ``period`` the record
interval and ``scan_period`` the time of one full scan (`SCAN_PERIOD_S`; ZephIR's
``Packets in Average``, when exported, is used as ``n_eff`` directly). The inversion
(`lidarjax.invert_reconstructed`) propagates a unit noise through the table's response;
the speed's standard deviation is that times ``noise_along`` and the direction's that times
``noise_cross`` (exact when the local distortion maps along-wind to along-wind, i.e. a
speed-up and a turning; the distortions a table describes are of this kind to first order).

The model treats the scans of an interval as independent samples: it is the instrument's
sampling noise, not the turbulent sampling error of a 10-minute mean (which a mast beside the
lidar shares). It ignores the bias of a scalar-averaged speed (``sigma_v**2 / 2U``, below
1 % above 5 m/s). Coverage on synthetic records with known noise (95 % intervals cover
the truth 93-97 % of the time): tests/workflows/test_records_uncertainty.py.
"""

from __future__ import annotations

import dataclasses
import math
import os
import warnings
from pathlib import Path

import numpy as np
from scipy.io import netcdf_file

from .._util import atomic_path
from ..angles import horizontal_speed, wind_direction
from ..flags import MIN_AVAILABILITY, InverseFlag, RecordFlag
from ..inverse import invert, invert_reconstructed
from ..io import RecordSet, read_rtd, read_sta, read_zephir_csv
from ..progress import AbstractProgress, TextProgress, progress_meter
from ..response import ResponseTable

__all__ = ["RecordSet", "CorrectedRecords", "load_records", "check_instrument",
           "tilt_difference",
           "match_heights", "reported_noise", "correct_records", "write_corrected_csv",
           "write_corrected_netcdf", "quality_summary", "SCAN_PERIOD_S",
           "DEFAULT_MIN_AVAILABILITY"]


#: Seconds per full scan, by instrument kind, for the standard error of reported records:
#: Windcube V2/V2.1 (4 tilted beams + vertical, about 1 s each), Windcube V1 (4 beams at about
#: 1.5 s), ZephIR 300/ZX (one 1-s rotation per height, heights cycled, about 3 heights per
#: cycle on average).
SCAN_PERIOD_S = {"windcube_v2": 5.0, "windcube_v1": 6.0, "zephir": 3.0}

#: Records whose data availability is below this (percent) are flagged LOW_AVAILABILITY and
#: not used: the readers' `MIN_AVAILABILITY` (80 %, wind-resource practice).
DEFAULT_MIN_AVAILABILITY = MIN_AVAILABILITY

#: Heights closer than this (m) are the same height.
HEIGHT_TOLERANCE_M = 0.5


# ------------------------------------------------------------------------------------------
# reading


def load_records(path, *, cnr_threshold: float | None = None, period: str = "10min",
                 min_availability: float = DEFAULT_MIN_AVAILABILITY,
                 progress: bool | AbstractProgress = False) -> RecordSet:
    """Read a record file (by suffix: ``.sta``/``.stdsta``, ``.rtd``/``.stdrtd``, ``.csv``).

    The reader's result converts itself (``to_record_set()``: `lidarjax.io.StaRecord`,
    `lidarjax.io.RtdRecord`, `lidarjax.io.ZephirRecord`). `cnr_threshold` (dB) overrides the
    ``.rtd`` header's `CNRThreshold`; `period` is the averaging interval of raw records;
    records below `min_availability` percent are flagged LOW_AVAILABILITY and not used. The
    reader's warnings (corrupt rows, by file and line) are collected in `RecordSet.warnings`
    instead of being printed. Values under a blocking flag are NaN. `progress`: a line on
    stderr while reading a Windcube file (True), or a `lidarjax.progress` meter. Raises
    `ValueError` naming the file for an unknown format or a file that cannot be read at all.
    """

    p = Path(path)
    suffix = p.suffix.lower()
    if suffix not in (".sta", ".stdsta", ".csv", ".rtd", ".stdrtd"):
        raise ValueError(f"{p}: unknown record format {suffix!r}; expected .sta, .stdsta, .rtd "
                         "or a ZephIR .csv")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        if suffix in (".rtd", ".stdrtd"):
            records = read_rtd(p, progress=progress).to_record_set(
                period, cnr_threshold="header" if cnr_threshold is None else float(cnr_threshold),
                min_availability=min_availability)
        elif suffix == ".csv":
            records = read_zephir_csv(p).to_record_set(min_availability=min_availability)
        else:
            records = read_sta(p, min_availability=min_availability,
                               progress=progress).to_record_set()
    notes = [str(w.message) for w in caught]
    notes += [w for w in records.warnings if w not in notes]
    return dataclasses.replace(records, warnings=tuple(notes))


# ------------------------------------------------------------------------------------------
# consistency


def _wrap(a: float) -> float:
    return (a + 180.0) % 360.0 - 180.0


def check_instrument(metadata: dict, table, records: RecordSet, *,
                     angle_tolerance: float = 1.0) -> list[str]:
    """Mismatches between a table's metadata and a record file's header, one text each
    ("scan angle: table 28 deg, record header ScanAngle=15 deg"). Facts either side does not
    state are skipped (see `table_warnings` for tables without metadata). The table's own
    `lidarjax.Instrument` fills what `metadata` does not say."""
    if table is not None and getattr(table, "instrument", None) is not None:
        metadata = {**table.instrument.metadata(), **metadata}
    out = []
    scan = str(metadata.get("scan", "") or "")
    inst = records.instrument
    if scan and inst and scan != inst:
        out.append(f"instrument: table built for {scan}, record file is from a {inst}")
    if scan and not inst:
        family = "zephir" if records.kind == "zephir" else "windcube"
        if not scan.startswith(family):
            out.append(f"instrument: table built for {scan}, record file is a {family} "
                       f"{records.kind} file")
    cone = metadata.get("cone_angle_deg")
    if isinstance(cone, (int, float)) and math.isfinite(records.scan_angle):
        if abs(float(cone) - records.scan_angle) > angle_tolerance:
            out.append(f"cone angle: table {cone:g} deg, record header ScanAngle="
                       f"{records.scan_angle:g} deg")
    if records.kind == "rtd":
        n_beams = metadata.get("n_beams", getattr(table, "n_beams", None))
        if isinstance(n_beams, int) and n_beams not in (4, 5):
            out.append(f"beam layout: table has {n_beams} beams, the .rtd file has 4 tilted "
                       "beams (0/90/180/270) and a vertical one")
    eps = metadata.get("epsilon_deg")
    if isinstance(eps, (int, float)) and math.isfinite(records.direction_offset):
        if abs(_wrap(float(eps) - records.direction_offset)) > angle_tolerance:
            out.append(f"direction offset: table epsilon {float(eps):g} deg (beam 0 points "
                       f"there, clockwise from north), record header DirectionOffset="
                       f"{records.direction_offset:g} deg")
    # tilt: compared in magnitude (the instruments' sign conventions for PitchAngle and
    # RollAngle are not stated in the files), with the same tolerance
    for name, key in (("pitch", "pitch_deg"), ("roll", "roll_deg")):
        tv, rv = metadata.get(key), getattr(records, name)
        if isinstance(tv, (int, float)) and math.isfinite(rv) and \
                abs(abs(float(tv)) - abs(rv)) > angle_tolerance:
            out.append(f"{name}: table {float(tv):g} deg, record header {rv:g} deg "
                       "(build the table with --pitch/--roll)")
    return out


def tilt_difference(metadata: dict, records: RecordSet, *, threshold: float = 0.05) -> str | None:
    """One line when the record header's tilt (PitchAngle, RollAngle) differs from the
    table's mount by more than `threshold` degrees (within `check_instrument`'s tolerance,
    else that refuses), or None."""
    diffs, parts = [], []
    for name, key in (("pitch", "pitch_deg"), ("roll", "roll_deg")):
        tv, rv = metadata.get(key, 0.0), getattr(records, name, math.nan)
        if not isinstance(tv, (int, float)) or not math.isfinite(rv):
            continue
        diffs.append(abs(float(tv) - rv))
        parts.append(f"{name} {rv:g} deg in the record header, {float(tv):g} in the table")
    if not diffs or max(diffs) <= threshold:
        return None
    return ("tilt: " + "; ".join(parts) + " (lidarjax table --heights-from RECORDS "
            "--tilt-from-records builds the table with the record's tilt)")


def table_warnings(metadata: dict) -> list[str]:
    """What an old table (without instrument metadata) cannot check."""
    missing = [k for k in ("scan", "cone_angle_deg", "epsilon_deg", "heights_m")
               if k not in metadata]
    if missing:
        return [f"the table has no {', '.join(missing)} metadata, so the instrument cannot be "
                "checked against the record header; rebuild it with this lidarjax table"]
    return []


def match_heights(table_heights, record_heights, *, tolerance: float = HEIGHT_TOLERANCE_M):
    """Pair table and record heights within `tolerance` metres.

    **Returns:** ``(table_index, record_index, record_only, table_only)``: index arrays of the
    common heights (ascending), and the record heights the table lacks and the table heights
    the record lacks (metres).
    """
    th = np.asarray(table_heights, np.float64).reshape(-1)
    rh = np.asarray(record_heights, np.float64).reshape(-1)
    ti, ri = [], []
    for i, h in enumerate(th):
        if rh.size == 0:
            break
        j = int(np.argmin(np.abs(rh - h)))
        if abs(rh[j] - h) <= tolerance and j not in ri:
            ti.append(i)
            ri.append(j)
    record_only = [float(h) for j, h in enumerate(rh) if j not in ri]
    table_only = [float(h) for i, h in enumerate(th) if i not in ti]
    return np.asarray(ti, int), np.asarray(ri, int), record_only, table_only


def subset_table(table, index):
    """The table restricted to the heights `index` (splines refitted; cheap)."""

    idx = np.asarray(index, int)
    if idx.size == table.n_heights and np.all(idx == np.arange(table.n_heights)):
        return table

    def take(a, axis=1):
        return None if a is None else np.take(np.asarray(a), idx, axis=axis)

    return ResponseTable(
        np.asarray(table.directions), take(table.response),
        reconstructed=take(table.reconstructed), point=take(table.point),
        beam_velocity=take(table.beam_velocity), beam_gradient=take(table.beam_gradient),
        beam_vectors=None if table.beam_vectors is None else np.asarray(table.beam_vectors),
        heights=take(table.heights, axis=0),
        instrument=None if table.instrument is None else dataclasses.replace(
            table.instrument, heights_m=None if table.instrument.heights_m is None
            else tuple(table.instrument.heights_m[i] for i in idx)))


# ------------------------------------------------------------------------------------------
# uncertainty


def reported_noise(speed, speed_std, *, availability=None, direction_std=None, n_samples=None,
                   period_s: float = 600.0, scan_period_s: float = 5.0):
    """Noise (m/s) of 10-minute reported records along and across the wind: the standard
    error of the interval mean (model in the module docstring).

    Arrays broadcast together: `speed`, `speed_std` (m/s), `availability` (percent),
    `direction_std` (degrees), `n_samples` (scans averaged, replaces availability). Returns
    ``(noise_along, noise_cross)``, NaN where the dispersion is unknown or not positive.
    """
    speed = np.asarray(speed, np.float64)
    su = np.asarray(speed_std, np.float64)
    if direction_std is not None:
        sv = np.abs(speed) * np.deg2rad(np.asarray(direction_std, np.float64))
        sv = np.where(np.isfinite(sv) & (sv > 0), sv, 0.8 * su)
    else:
        sv = 0.8 * su
    if n_samples is not None:
        n_eff = np.asarray(n_samples, np.float64)
    else:
        a = 1.0 if availability is None else np.asarray(availability, np.float64) / 100.0
        a = np.where(np.isfinite(a), np.clip(a, 0.0, 1.0), 1.0)
        n_eff = a * float(period_s) / float(scan_period_s)
    ok = (su > 0) & np.isfinite(su) & (n_eff > 0)
    root = np.sqrt(np.maximum(n_eff, 1.0))
    with np.errstate(invalid="ignore"):
        along = np.where(ok, su / root, np.nan)
        cross = np.where(ok, sv / root, np.nan)
    return along, cross


# ------------------------------------------------------------------------------------------
# correcting


@dataclasses.dataclass(frozen=True)
class CorrectedRecords:
    """Corrected records (`correct_records`); arrays ``(r, h)`` unless noted.

    - `kind`: 'sta', 'rtd' or 'zephir'; `time` ``(r,)`` datetime64 (end of interval);
      `heights` ``(h,)`` m above the lidar (those both the table and the record have);
    - `speed`, `direction`: free-stream horizontal speed (m/s) and meteorological direction
      (degrees), NaN where not converged; `speed_std`, `direction_std`: one-sigma;
    - `converged`, `flags` (`lidarjax.InverseFlag` bits), `record_flags` (the reader's
      `RecordFlag` bits: why the file's value is missing or doubtful);
    - `measured_speed`, `measured_direction`: what the instrument reported (for raw LOS
      records, the homogeneous-flow reconstruction);
    - `noise`: the noise level used (m/s; given, from the record's dispersion, or estimated
      from spare beams); `availability`: percent, NaN when the file has none;
    - `record_only_heights`, `table_only_heights`: heights (m) not corrected because the
      other side lacks them; `warnings`: lines the reader reported.
    """

    kind: str
    time: np.ndarray
    heights: np.ndarray
    speed: np.ndarray
    direction: np.ndarray
    speed_std: np.ndarray
    direction_std: np.ndarray
    converged: np.ndarray
    flags: np.ndarray
    measured_speed: np.ndarray
    measured_direction: np.ndarray
    noise: np.ndarray | None = None
    availability: np.ndarray | None = None
    record_flags: np.ndarray | None = None
    record_only_heights: tuple[float, ...] = ()
    table_only_heights: tuple[float, ...] = ()
    warnings: tuple[str, ...] = ()


def _progress(label: str, progress):
    """A ``(done, total)`` callback reporting through the meter `progress` asks for (True: a
    one-line bar on stderr, `lidarjax.progress.TextProgress`)."""
    return progress_meter(progress, TextProgress).callback(label)


def _homogeneous(los, vectors):
    """The homogeneous-flow reconstruction ``(r, h, 3)`` from the finite beams of each
    record (least squares over the beams present; NaN when they cannot fix all three
    components). `vectors` ``(b, 3)`` in the north frame, or None."""
    if vectors is None:
        return np.full(los.shape[:-1] + (3,), np.nan)
    n = np.asarray(vectors, np.float64)
    ok = np.isfinite(los)
    w = ok.astype(np.float64)
    y = np.where(ok, los, 0.0)
    a = np.einsum("...b,bi,bj->...ij", w, n, n)
    rhs = np.einsum("...b,bi->...i", w * y, n)
    eig = np.linalg.eigvalsh(a)
    good = eig[..., 0] > 1e-6 * np.maximum(eig[..., -1], 1e-300)
    a = np.where(good[..., None, None], a, np.eye(3))
    v = np.linalg.solve(a, rhs[..., None])[..., 0]
    v[~good] = np.nan
    return v


def correct_records(
    table,
    path,
    *,
    noise: float | None = None,
    chunk_records: int = 8192,
    progress: bool | AbstractProgress = False,
    records: RecordSet | None = None,
    scan_period_s: float | None = None,
    cnr_threshold: float | None = None,
    min_availability: float = DEFAULT_MIN_AVAILABILITY,
) -> CorrectedRecords:
    """Read a record file and invert every record and height with `table`.

    - ``.sta`` / ``.stdsta`` (Windcube statistics) and ZephIR ``.csv``:
      `lidarjax.invert_reconstructed` on the reported speed and direction. `noise` is the
      noise of each reported component (m/s); without it, the record's own dispersion and
      availability give it (`reported_noise`, model in the module docstring);
    - ``.rtd`` (Windcube real-time LOS): 10-minute beam means after the CNR filter (the
      header's `CNRThreshold`, or `cnr_threshold`), then `lidarjax.invert` on the raw LOS
      (noise estimated from the spare beams unless `noise` is given).

    Only heights both the table and the record have (within 0.5 m) are corrected; the others
    are listed in `record_only_heights` / `table_only_heights`. Records are processed in
    chunks of `chunk_records` (one compiled shape; the last chunk is padded), with a progress
    line when asked. Bad records come back NaN with a reason in `flags`, never an exception.
    Pass an already loaded `records` to skip reading `path`.
    """

    rec, ti, ri, record_only, table_only = _matched_records(
        table, path, records, noise, cnr_threshold, min_availability)
    if ti.size == 0:
        raise ValueError(
            f"{rec.path}: none of the table's heights "
            f"({', '.join(f'{h:g}' for h in np.asarray(table.heights))} m) is among the "
            f"record's ({', '.join(f'{h:g}' for h in rec.heights)} m); build the table at the "
            "record's heights (lidarjax table --heights-from RECORDS)")
    sub = subset_table(table, ti)
    n, h = rec.time.size, ti.size
    anisotropic = None
    if rec.kind == "rtd":
        los, measured = _rtd_los(rec, ri, sub)
        data = (los,)
        noise_arr = None if noise is None else np.full((n, h), float(noise))
    else:
        speed, direction = rec.speed[:, ri], rec.direction[:, ri]
        data = (speed, direction)
        measured = (speed, direction)
        if noise is not None:
            noise_arr = np.full((n, h), float(noise))
        elif rec.speed_std is not None:
            # invert with unit noise, then scale speed_std along and direction_std across
            anisotropic = _reported_noise(rec, ri, speed, scan_period_s)
            noise_arr = np.where(np.isfinite(anisotropic[0]), 1.0, np.nan)
        else:
            noise_arr = None
    show = _progress(f"correcting {Path(rec.path).name}", progress)
    out = _invert_in_chunks(sub, rec.kind, data, noise_arr, chunk_records, show)
    if anisotropic is not None:
        out["speed_std"] *= anisotropic[0]
        out["direction_std"] *= anisotropic[1]
        out["noise"] = np.where(np.isfinite(out["noise"]), anisotropic[0], np.nan)
    avail = None if rec.availability is None else np.asarray(rec.availability)[:, ri]
    return CorrectedRecords(
        kind=rec.kind, time=np.asarray(rec.time),
        heights=np.asarray(rec.heights, np.float64)[ri],
        measured_speed=np.asarray(measured[0], np.float64),
        measured_direction=np.asarray(measured[1], np.float64),
        availability=avail, record_flags=np.asarray(rec.flags[:, ri], np.int64),
        record_only_heights=tuple(record_only), table_only_heights=tuple(table_only),
        warnings=rec.warnings, **out)


def _matched_records(table, path, records, noise, cnr_threshold, min_availability):
    """The records (`records`, or `path` read) and the heights both they and `table` have
    (`match_heights`), after checking `noise` and that the table knows its heights."""
    rec = records if records is not None else load_records(
        path, cnr_threshold=cnr_threshold, min_availability=min_availability)
    if noise is not None and not (math.isfinite(float(noise)) and float(noise) > 0):
        raise ValueError(f"noise must be a finite positive number (m/s), got {noise}")
    if table.heights is None:
        raise ValueError("the response table has no heights; rebuild it with lidarjax table")
    ti, ri, record_only, table_only = match_heights(table.heights, rec.heights)
    return rec, ti, ri, record_only, table_only


def _rtd_los(rec, ri, sub, dtype=None):
    """Raw LOS records ``(r, h, b)`` at the record heights `ri` and the table's beams (cast
    to `dtype` when given) and the homogeneous-flow speed and direction they give."""
    if sub.n_beams > rec.los.shape[-1]:
        raise ValueError(f"{rec.path}: the table has {sub.n_beams} beams, the record "
                         f"{rec.los.shape[-1]}")
    los = rec.los[:, ri, : sub.n_beams]
    if dtype is not None:
        los = np.asarray(los, dtype)
    vectors = np.asarray(sub.beam_vectors) if sub.beam_vectors is not None else None
    homog = _homogeneous(los, vectors)
    return los, (np.asarray(horizontal_speed(homog)), np.asarray(wind_direction(homog)))


def _reported_noise(rec, ri, speed, scan_period_s):
    """The noise along and across the reported wind ``(r, h)`` (m/s) from the record's own
    dispersion and availability (`reported_noise`)."""
    period = rec.period_s if rec.period_s > 0 else 600.0
    sp = scan_period_s or SCAN_PERIOD_S.get(rec.instrument or (
        "zephir" if rec.kind == "zephir" else "windcube_v2"), 5.0)

    def pick(a):
        return None if a is None else np.asarray(a)[:, ri]

    return reported_noise(speed, pick(rec.speed_std), availability=pick(rec.availability),
                          direction_std=pick(rec.direction_std),
                          n_samples=pick(rec.n_samples), period_s=period, scan_period_s=sp)


def _invert_in_chunks(sub, kind, data, noise_arr, chunk_records, show):
    """`invert` (raw LOS, ``kind == "rtd"``) or `invert_reconstructed` of the records
    ``data`` in chunks of one compiled shape (the last padded with NaN records); records
    without a usable noise level get NaN uncertainties and `NO_NOISE_ESTIMATE`."""
    dtype = np.asarray(sub.response).dtype
    n, h = data[0].shape[:2]
    out = {k: np.empty((n, h), np.float64) for k in ("speed", "direction", "speed_std",
                                                      "direction_std", "noise")}
    out["converged"] = np.zeros((n, h), bool)
    out["flags"] = np.zeros((n, h), np.int64)
    # chunk shape: a power of two >= 64 (files of similar length share one compilation, in
    # this process and in the persistent cache), at most chunk_records
    size = max(1, min(int(chunk_records), max(64, 1 << max(n - 1, 0).bit_length())))
    show(0, n)
    for s in range(0, n, size):
        part = [np.asarray(a[s:s + size], dtype) for a in data]
        m = part[0].shape[0]
        npart = None if noise_arr is None else np.asarray(noise_arr[s:s + size], dtype)
        if m < size:  # pad to the compiled shape with NaN records
            part = [np.concatenate([a, np.full((size - m,) + a.shape[1:], np.nan, dtype)])
                    for a in part]
            if npart is not None:
                npart = np.concatenate([npart, np.full((size - m, h), np.nan, dtype)])
        if npart is not None:
            # records without a usable noise level get a placeholder (their std is NaN below)
            no_noise = ~(npart > 0)
            npart = np.where(no_noise, 1.0, npart)
        if kind == "rtd":
            inv = invert(sub, part[0], noise=npart)
        else:
            inv = invert_reconstructed(sub, part[0], part[1], noise=npart)
        for k in out:
            out[k][s:s + m] = np.asarray(getattr(inv, k))[:m]
        if npart is not None and np.any(no_noise[:m]):
            nn = no_noise[:m]
            for k in ("speed_std", "direction_std", "noise"):
                out[k][s:s + m][nn] = np.nan
            conv = out["converged"][s:s + m]

            out["flags"][s:s + m] |= np.where(nn & conv, int(InverseFlag.NO_NOISE_ESTIMATE), 0)
        show(min(n, s + size), n)
    return out


# ------------------------------------------------------------------------------------------
# writing

def _flag_doc() -> str:
    inv = ", ".join(f"{int(f)} {f.name.lower()}" for f in InverseFlag if f)
    rec = ", ".join(f"{int(f)} {f.name.lower()}" for f in RecordFlag if f)
    return f"flags (lidarjax.InverseFlag bits): {inv}; record_flags (RecordFlag bits): {rec}"


def _text_bytes(values: np.ndarray, decimals: int, width: int = 0) -> np.ndarray:
    """Fixed-point text of a float array as a right-aligned ``(n, width)`` uint8 array padded
    with zero bytes (dropped when the row is assembled): ``-12.3456``, ``nan``, ``inf``.
    Vectorised over the values (one numpy pass per character position)."""
    a = np.asarray(values, np.float64).reshape(-1)
    finite = np.isfinite(a)
    scale = 10 ** decimals
    big = finite & (np.abs(a) >= 1e12)
    m = np.round(np.abs(np.where(finite & ~big, a, 0.0)) * scale).astype(np.int64)
    neg = finite & ~big & (a < 0) & (m > 0)
    width = width or (14 + decimals)
    out = np.zeros((a.size, width), np.uint8)
    pos = width - 1
    for _ in range(decimals):
        out[:, pos] = 48 + m % 10
        m //= 10
        pos -= 1
    if decimals:
        out[:, pos] = 46  # "."
        pos -= 1
    out[:, pos] = 48 + m % 10  # at least one integer digit
    m //= 10
    start = np.full(a.size, pos)
    pos -= 1
    while pos > 0 and m.any():
        more = m > 0
        out[more, pos] = 48 + m[more] % 10
        start[more] = pos
        m //= 10
        pos -= 1
    out[neg, start[neg] - 1] = 45  # "-"
    special = ((b"nan", np.isnan(a)), (b"inf", np.isposinf(a)), (b"-inf", np.isneginf(a)))
    for text, mask in special:
        if mask.any():
            out[mask] = 0
            out[np.ix_(mask, np.arange(width - len(text), width))] = np.frombuffer(text, np.uint8)
    if big.any():  # beyond fixed point: Python's repr (rare: never a wind speed)
        out[big] = 0
        for i in np.flatnonzero(big):
            t = repr(float(a[i])).encode()[:width]
            out[i, width - len(t):] = np.frombuffer(t, np.uint8)
    return out


def _const_bytes(texts, index) -> np.ndarray:
    """``(n, w)`` uint8 rows of the byte strings `texts[index]`, zero-padded on the right."""
    arr = np.asarray(texts, dtype="S")
    return arr.view(np.uint8).reshape(arr.size, -1)[np.asarray(index)]


def _csv_chunk(columns: list[np.ndarray]) -> bytes:
    """Join ``(n, w_i)`` uint8 text columns with commas and newlines, dropping zero bytes."""
    n = columns[0].shape[0]
    comma = np.full((n, 1), 44, np.uint8)
    parts = []
    for i, c in enumerate(columns):
        parts.append(c)
        parts.append(comma if i < len(columns) - 1 else np.full((n, 1), 10, np.uint8))
    block = np.concatenate(parts, axis=1)
    return block[block != 0].tobytes()


def write_corrected_csv(path, corrected: CorrectedRecords, metadata: dict | None = None, *,
                        progress: bool | AbstractProgress = False, chunk_records: int = 8192):
    """Write corrected records as a long CSV (one row per record and height), atomically and
    in chunks (bounded memory).

    Header comment lines carry `metadata` and the flag bits; columns: time (ISO 8601, UTC,
    end of interval), height [m], speed [m/s], direction [deg, meteorological: from,
    clockwise from north], speed_std [m/s], direction_std [deg], converged [bool],
    flags [bits], measured_speed [m/s], measured_direction [deg], availability [%],
    noise [m/s]. Speeds with 4 decimals, directions 3, availability 1.
    """

    c = corrected
    n, h = c.speed.shape if c.speed.ndim == 2 else (0, c.heights.size)
    show = _progress("writing CSV", progress)
    target = Path(path)
    head = [f"# {k}: {v}" for k, v in (metadata or {}).items()]
    head.append(f"# {_flag_doc()}")
    head.append("time,height [m],speed [m/s],direction [deg],speed_std [m/s],"
                "direction_std [deg],converged,flags,record_flags,measured_speed [m/s],"
                "measured_direction [deg],availability [%],noise [m/s]")
    heights = [f"{x:g}".encode() for x in c.heights]
    avail = c.availability if c.availability is not None else np.full((n, h), np.nan)
    noise = c.noise if c.noise is not None else np.full((n, h), np.nan)
    rflags = c.record_flags if c.record_flags is not None else np.zeros((n, h), np.int64)
    with atomic_path(target) as tmp, open(tmp, "xb") as fh:
        fh.write(("\n".join(head) + "\n").encode())
        show(0, n)
        for s in range(0, n, chunk_records):
            e = min(n, s + chunk_records)
            m = e - s
            stamps = np.char.add(np.datetime_as_string(
                np.asarray(c.time[s:e]).astype("datetime64[s]"), unit="s"), "Z").astype("S")
            cols = [
                _const_bytes(stamps, np.repeat(np.arange(m), h)),
                _const_bytes(heights, np.tile(np.arange(h), m)),
                _text_bytes(c.speed[s:e], 4), _text_bytes(c.direction[s:e], 3),
                _text_bytes(c.speed_std[s:e], 4), _text_bytes(c.direction_std[s:e], 3),
                _const_bytes([b"False", b"True"], np.asarray(c.converged[s:e]).astype(int).ravel()),
                _text_bytes(np.asarray(c.flags[s:e], np.float64), 0),
                _text_bytes(np.asarray(rflags[s:e], np.float64), 0),
                _text_bytes(c.measured_speed[s:e], 4), _text_bytes(c.measured_direction[s:e], 3),
                _text_bytes(avail[s:e], 1), _text_bytes(noise[s:e], 4),
            ]
            fh.write(_csv_chunk(cols))
            show(e, n)
    return target


def write_corrected_netcdf(path, corrected: CorrectedRecords, metadata: dict | None = None):
    """Write corrected records as a CF-1.8 NetCDF file (classic format), atomically.

    Written with `scipy.io.netcdf_file` (a core dependency: no xarray needed, and no second
    of importing it); any NetCDF reader opens it (xarray, netCDF4, ncdump). Dimensions
    ``time`` (end of interval, UTC, seconds since 1970-01-01) and ``height`` (m); every
    variable has `units` and `long_name`, `standard_name` where CF has one (`wind_speed`,
    `wind_from_direction`), `_FillValue` NaN; `flags` carries CF `flag_masks` and
    `flag_meanings` (`InverseFlag` and `RecordFlag` bits), `converged` `flag_values`.
    """

    c = corrected
    n, h = np.shape(c.speed)
    target = Path(path)
    with atomic_path(target) as tmp:
        nc = netcdf_file(os.fspath(tmp), "w", version=2)
        try:
            nc.Conventions = "CF-1.8"
            nc.title = "lidarjax corrected lidar records"
            nc.history = "lidarjax correct"
            for k, v in (metadata or {}).items():
                setattr(nc, str(k).replace(" ", "_"), str(v))
            nc.createDimension("time", n)
            nc.createDimension("height", h)
            t = nc.createVariable("time", "f8", ("time",))
            t[:] = np.asarray(c.time).astype("datetime64[s]").astype(np.int64).astype(np.float64)
            t.units = "seconds since 1970-01-01 00:00:00"
            t.calendar = "standard"
            t.standard_name = "time"
            t.long_name = "end of the averaging interval (UTC)"
            z = nc.createVariable("height", "f8", ("height",))
            z[:] = np.asarray(c.heights, np.float64)
            z.units = "m"
            z.positive = "up"
            z.long_name = "height above the lidar"

            def var(name, values, units, long_name, standard_name=None):
                v = nc.createVariable(name, "f4", ("time", "height"))
                v._FillValue = np.float32(np.nan)
                v[:] = np.asarray(values, np.float32)
                v.units = units
                v.long_name = long_name
                if standard_name:
                    v.standard_name = standard_name

            var("speed", c.speed, "m s-1", "free-stream horizontal wind speed", "wind_speed")
            var("direction", c.direction, "degree", "free-stream wind direction (from, "
                "clockwise from north)", "wind_from_direction")
            var("speed_std", c.speed_std, "m s-1", "one-sigma uncertainty of speed")
            var("direction_std", c.direction_std, "degree", "one-sigma uncertainty of direction")
            var("measured_speed", c.measured_speed, "m s-1", "horizontal wind speed reported by "
                "the instrument", "wind_speed")
            var("measured_direction", c.measured_direction, "degree", "wind direction reported "
                "by the instrument", "wind_from_direction")
            if c.availability is not None:
                var("availability", c.availability, "percent", "data availability")
            if c.noise is not None:
                var("noise", c.noise, "m s-1", "noise level used for the uncertainty (along "
                    "the wind)")
            cv = nc.createVariable("converged", "i1", ("time", "height"))
            cv[:] = np.asarray(c.converged).astype(np.int8)
            cv.long_name = "inversion converged"
            cv.flag_values = np.array([0, 1], np.int8)
            cv.flag_meanings = "false true"
            rflags = c.record_flags if c.record_flags is not None else np.zeros((n, h))
            for name, values, kind, long_name in (
                    ("flags", c.flags, InverseFlag, "inversion flags (lidarjax.InverseFlag)"),
                    ("record_flags", rflags, RecordFlag, "record flags from the file "
                     "(RecordFlag)")):
                fl = nc.createVariable(name, "i4", ("time", "height"))
                fl[:] = np.asarray(values).astype(np.int32)
                fl.long_name = long_name
                fl.flag_masks = np.array([int(f) for f in kind if f], np.int32)
                fl.flag_meanings = " ".join(f.name.lower() for f in kind if f)
            nc.flush()
        finally:
            nc.close()
    return target


def quality_summary(c: CorrectedRecords) -> list[str]:
    """Lines for the end of `lidarjax correct`: converged share, availability, flags by kind."""

    total = c.converged.size
    ok = int(np.count_nonzero(c.converged))
    lines = [f"converged {ok} of {total} record-heights ({100 * ok / max(total, 1):.1f} %; "
             f"{c.time.size} records x {c.heights.size} heights)"]
    if c.availability is not None and np.isfinite(c.availability).any():
        a = np.where(np.isfinite(c.availability), c.availability, np.inf)
        lines.append(f"availability: median {np.nanmedian(c.availability):.1f} %, below "
                     f"{DEFAULT_MIN_AVAILABILITY:g} %: {int(np.count_nonzero(a < DEFAULT_MIN_AVAILABILITY))}")
    counts = []
    rflags = c.record_flags if c.record_flags is not None else np.zeros_like(c.flags)
    for values, kind in ((rflags, RecordFlag), (c.flags, InverseFlag)):
        for flag in kind:
            k = int(np.count_nonzero(np.asarray(values) & int(flag))) if flag else 0
            if k:
                counts.append(f"{flag.name.lower()} {k}")
    lines.append("flags: " + (", ".join(counts) if counts else "none"))
    if c.converged.any():
        du = np.abs(c.speed - c.measured_speed)[c.converged]
        std = c.speed_std[c.converged]
        du_text = (f"median |correction| {np.nanmedian(du):.3f} m/s" if np.isfinite(du).any()
                   else "no reported speed to compare")
        std_text = (f"median speed_std {np.nanmedian(std):.3f} m/s" if np.isfinite(std).any()
                    else "no uncertainty (no dispersion in the file; give --noise)")
        lines.append(f"{du_text}; {std_text}")
    return lines
