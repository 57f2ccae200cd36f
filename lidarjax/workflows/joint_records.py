"""Correcting lidar records jointly across heights with a `ProfileTable` (`lidarjax correct
--joint`): one solution per record (reference-height speed, direction, profile parameter),
reported per height as `CorrectedRecords` plus the per-record profile solution.

A table without a profile axis (a `ResponseTable`) falls back to the per-height
`lidarjax.correct_records`, and the returned note says so.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..inverse import JointInversion, invert_joint, invert_joint_reconstructed
from ..response import ProfileTable, ResponseTable
from .records import (
    DEFAULT_MIN_AVAILABILITY,
    CorrectedRecords,
    _matched_records,
    _rtd_los,
    correct_records,
    subset_table,
)

__all__ = ["correct_records_joint", "JointCorrected"]


@dataclasses.dataclass(frozen=True)
class JointCorrected:
    """`correct_records_joint`'s result: `corrected` (per height, as `correct_records`),
    `joint` (the per-record `lidarjax.JointInversion`, None after a fallback), `note` (one
    line when the table had no profile axis, else None)."""

    corrected: CorrectedRecords
    joint: JointInversion | None
    note: str | None


def _subset_profile_table(table: ProfileTable, index) -> ProfileTable:
    return ProfileTable(table.name, np.asarray(table.parameters),
                        [subset_table(t, index) for t in table.tables], profile=table.profile)


def correct_records_joint(table, path, *, noise: float | None = None, records=None,
                          cnr_threshold: float | None = None,
                          min_availability: float = DEFAULT_MIN_AVAILABILITY,
                          progress=False) -> JointCorrected:
    """Read a record file and invert every record jointly over the heights it shares with
    `table` (`lidarjax.invert_joint` on ``.rtd`` LOS, `lidarjax.invert_joint_reconstructed`
    on reported ``.sta``/ZephIR winds). `noise` (m/s) is the LOS (or reported component)
    noise; None estimates one level per record from the residuals.

    With a `ResponseTable` (no profile axis) it runs `lidarjax.correct_records` per height
    instead and says so in `note`.
    """
    if isinstance(table, ResponseTable):
        corrected = correct_records(table, path, noise=noise, records=records,
                                    cnr_threshold=cnr_threshold,
                                    min_availability=min_availability, progress=progress)
        return JointCorrected(corrected, None, "the table has no profile axis (it was built "
                              "without --param); corrected per height instead")
    if not isinstance(table, ProfileTable):
        raise ValueError(f"correct_records_joint: `table` must be a ProfileTable, got "
                         f"{type(table).__name__}")
    rec, ti, ri, record_only, table_only = _matched_records(
        table, path, records, noise, cnr_threshold, min_availability)
    if ti.size < 2:
        raise ValueError(f"{rec.path}: the joint inversion needs at least two heights shared by "
                         f"the table and the record, found {ti.size}")
    sub = _subset_profile_table(table, ti)
    n, h = rec.time.size, ti.size
    dtype = np.asarray(sub.response).dtype
    noise_arr = None if noise is None else np.full((n, h), float(noise), dtype)
    if rec.kind == "rtd":
        los, measured = _rtd_los(rec, ri, sub, dtype)
        joint = invert_joint(sub, los, noise=noise_arr)
    else:
        speed = np.asarray(rec.speed[:, ri], dtype)
        direction = np.asarray(rec.direction[:, ri], dtype)
        measured = (speed, direction)
        joint = invert_joint_reconstructed(sub, speed, direction, noise=noise_arr)

    def per_height(a):
        return np.broadcast_to(np.asarray(a)[:, None], (n, h)).copy()

    avail = None if rec.availability is None else np.asarray(rec.availability)[:, ri]
    corrected = CorrectedRecords(
        kind=rec.kind, time=np.asarray(rec.time),
        heights=np.asarray(rec.heights, np.float64)[ri],
        speed=np.asarray(joint.height_speed, np.float64),
        direction=per_height(np.asarray(joint.direction, np.float64)),
        speed_std=np.asarray(joint.height_speed_std, np.float64),
        direction_std=per_height(np.asarray(joint.direction_std, np.float64)),
        converged=per_height(joint.converged), flags=per_height(np.asarray(joint.flags,
                                                                          np.int64)),
        measured_speed=np.asarray(measured[0], np.float64),
        measured_direction=np.asarray(measured[1], np.float64),
        noise=per_height(np.asarray(joint.noise, np.float64)), availability=avail,
        record_flags=np.asarray(rec.flags[:, ri], np.int64),
        record_only_heights=tuple(record_only), table_only_heights=tuple(table_only),
        warnings=rec.warnings)
    return JointCorrected(corrected, joint, None)
