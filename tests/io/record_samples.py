"""Synthetic instrument files written by the tests (never copies of real files).

Each writer returns text in the layout of a real export; `tests/io/test_records_*.py`
use them. Values are deterministic so that good rows can be compared exactly.
"""

from __future__ import annotations

import datetime as dt

DEG = "\u00b0"
V2_HEIGHTS = (40, 60)
STA_QUANTITIES = ("Wind Speed (m/s)", "Wind Speed Dispersion (m/s)",
                  f"Wind Direction ({DEG})", "Z-wind (m/s)", "CNR (dB)", "Data Availability (%)")


def sta_values(i: int, j: int) -> list[float]:
    """Row `i`, height `j`: speed, dispersion, direction, Z-wind, CNR, availability."""
    return [5.0 + i + j, 0.5, 200.0 + 3 * i + j, 0.01 * (i - j), -12.0 - j, 100.0 - i]


def sta_v2_text(n: int = 6, *, step_min: int = 10, timezone: str = "UTC+0",
                extra_header: tuple[str, ...] = (), start=dt.datetime(2020, 10, 7, 0, 0)) -> str:
    """A Windcube V2/V2.1 `.sta` (10-minute, or 1-minute with `step_min=1`)."""
    header = ["Version=WF 2.1.6.16036", "ID System=WLS71072", f"timezone={timezone}",
              "********************", f"ScanAngle ({DEG})=NA", f"DirectionOffset ({DEG})=-37",
              f"PitchAngle ({DEG})=0.08", f"RollAngle ({DEG})=-0.819", "CNRThreshold=-24",
              *extra_header, "Altitudes (m)=\t" + "\t".join(str(h) for h in V2_HEIGHTS)]
    cols = ["Timestamp (end of interval)", f"Int Temp ({DEG}C)", "Wiper count"]
    for h in V2_HEIGHTS:
        cols += [f"{h}m {q}" for q in STA_QUANTITIES] + [""]
    lines = [f"HeaderSize={len(header)}", *header, "********************", "\t".join(cols)]
    for i in range(n):
        stamp = (start + dt.timedelta(minutes=step_min * (i + 1))).strftime("%Y/%m/%d %H:%M")
        row = [stamp, "11.90", "0"]
        for j in range(len(V2_HEIGHTS)):
            row += [f"{v:.2f}" for v in sta_values(i, j)] + [""]
        lines.append("\t".join(row))
    return "\n".join(lines) + "\n"


V1_HEIGHTS = (40, 60, 80)
V1_PREFIXES = ("Vhm", "dVh", "VhMax", "VhMin", "Azim", "um", "vm", "wm", "dw", "CNRm",
               "sigmafreqm", "Avail")


def v1_values(i: int, j: int) -> list[float]:
    speed = 6.0 + i + 0.5 * j
    return [speed, 0.4, speed + 1, speed - 1, 250.0 + j, 5.0, 2.0, 0.05 * j, 0.2, -15.0 - j,
            1.5, 98.0]


def sta_v1_text(n: int = 4, *, split_date: bool = False) -> str:
    """A Windcube V1 `.sta`: `HeaderLength=`, gate-numbered columns, day-first stamps."""
    header = ["ID System=WLS7-0042", "Localisation=Test site",
              "Altitudes(m)=\t" + "\t".join(str(h) for h in V1_HEIGHTS),
              f"ScanAngle({DEG})=30", f"DirectionOffset({DEG})=12.5", "timezone=UTC+1"]
    cols = ["Date", "Wiper", "Vbatt", "Tint"]
    for g in range(1, len(V1_HEIGHTS) + 1):
        cols += [f"{p}{g}" for p in V1_PREFIXES]
    lines = [f"HeaderLength={len(header)}", *header, "\t".join(cols)]
    for i in range(n):
        t = dt.datetime(2012, 9, 1, 0, 10) + dt.timedelta(minutes=10 * i)
        stamp = t.strftime("%d/%m/%Y\t%H:%M:%S" if split_date else "%d/%m/%Y %H:%M:%S")
        row = [stamp, "0", "12.1", "21.5"]
        for j in range(len(V1_HEIGHTS)):
            row += [f"{v:.2f}" for v in v1_values(i, j)]
        lines.append("\t".join(row))
    return "\r\n".join(lines) + "\r\n"


def rtd_v2_text(n_cycles: int = 3, *, timezone: str = "UTC--3", cnr_v: float = -30.0) -> str:
    """A Windcube V2.1 `.rtd`: 0/90/180/270/V, one line of sight per 0.8 s."""
    header = ["Version=WF 2.1.5.15771", f"timezone={timezone}", f"ScanAngle ({DEG})=NA",
              f"DirectionOffset ({DEG})=0", f"PitchAngle ({DEG})=0.379",
              f"RollAngle ({DEG})=0.262", "CNRThreshold=-23", "Altitudes (m)=\t40\t60"]
    cols = ["Timestamp", "Position", "Temperature", "Wiper Count"]
    for h in (40, 60):
        cols += [f"{h}m CNR (dB)", f"{h}m Radial Wind Speed (m/s)",
                 f"{h}m Radial Wind Speed Dispersion (m/s)", ""]
    lines = [f"HeaderSize={len(header)}", *header, "********************", "\t".join(cols)]
    t0 = dt.datetime(2024, 8, 2, 23, 59, 50)
    k = 0
    for _c in range(n_cycles):
        for pos, rws in (("V", 0.1), ("0", -0.5), ("90", 3.4), ("180", 0.5), ("270", -3.4)):
            t = t0 + dt.timedelta(milliseconds=800 * k)
            stamp = t.strftime("%Y/%m/%d %H:%M:%S.") + f"{t.microsecond // 10000:02d}"
            cnr = cnr_v if pos == "V" else -10.0
            row = [stamp, pos, "23.1", "0"]
            for j in range(2):
                row += [f"{cnr - j:.2f}", f"{rws + 0.1 * j:.2f}", "0.02", ""]
            lines.append("\t".join(row))
            k += 1
    return "\n".join(lines) + "\n"


ZEPHIR_COLUMNS = ["Time and Date", "Reference", "Horizontal Wind Speed (m/s) at 38m",
                  "Wind Direction (deg) at 38m", "Vertical Wind Speed (m/s) at 38m",
                  "Horizontal Wind Speed (m/s) at 100m", "Wind Direction (deg) at 100m",
                  "Vertical Wind Speed (m/s) at 100m", "Packets in Average at 38m"]


def zephir_values(i: int) -> list[float]:
    return [7.0 + i, 250.0 + i, 0.1, 8.5 + i, 255.0 + i, -0.1, 60.0]


def zephir_300_text(n: int = 5, *, zone_line: str = "Time Zone;UTC+01:00") -> str:
    """A ZephIR 300 export: `;` separated, decimal commas, day-first, start-stamped."""
    pre = ["ZephIR 300 Waltz export;Unit 412", "Site;Test site", zone_line,
           "Time stamp;Start of averaging period", "Averaging period;10 min"]
    lines = [*pre, ";".join(ZEPHIR_COLUMNS)]
    for i in range(n):
        t = dt.datetime(2021, 9, 1, 0, 0) + dt.timedelta(minutes=10 * i)
        vals = [f"{v:.2f}".replace(".", ",") for v in zephir_values(i)]
        lines.append(";".join([t.strftime("%d/%m/%Y %H:%M:%S"), f"R{i}", *vals]))
    return "\r\n".join(lines) + "\r\n"


def zx_text(n: int = 5) -> str:
    """A ZX 300 export: `,` separated, ISO stamps, zone in the time column's name."""
    cols = ["Timestamp (UTC-05:00)", *ZEPHIR_COLUMNS[1:]]
    lines = ["ZX Lidars ZX300 unit 1188,CSV export", "Averaging period (s),600",
             ",".join(cols)]
    for i in range(n):
        t = dt.datetime(2022, 3, 4, 10, 0) + dt.timedelta(minutes=10 * i)
        vals = [f"{v:.2f}" for v in zephir_values(i)]
        lines.append(",".join([t.strftime("%Y-%m-%d %H:%M:%S"), f"R{i}", *vals]))
    return "\n".join(lines) + "\n"
