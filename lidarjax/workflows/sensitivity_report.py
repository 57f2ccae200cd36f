"""Installation uncertainty budgets of a seed settings.dat's lidar, for every platform
rotation in one compiled batch (the job of ``lidarjax sensitivity``).

`sensitivity_report` builds the `lidarjax.Mount` of each platform rotation (beta row) of a
`lidarjax.io.Settings` (its location row, gamma, psi, epsilon, and the installation's pitch
and roll), calls `lidarjax.uncertainty` on the CFD runs of all rotations at once (GUM law
of propagation ``u^2 = J C J^T`` with exact forward-mode Jacobians, optionally checked by
Monte Carlo) and returns a `SensitivityReport`. `write_sensitivity_report` writes it.

Units and frames: the inputs' standard uncertainties in their own units (degrees for
angles, metres for the location ``x, y, z`` in the CFD frame and for heights, m/s for the
free stream ``speed``; see `lidarjax.sensitivity.INPUTS`); heights in metres above the
lidar; ``z/H`` = (lidar z + height) / H with H the reference height (default the lidars'
mean z, i.e. their height above the CFD ``z = 0``); the free stream ``u_ref`` in the CFD
frame, m/s.

`write_sensitivity_report` writes to a folder:

- ``budget_<output>.csv``: one row per beta and height: the nominal value, the combined
  standard uncertainty, each input's contribution, variance share and sensitivity
  coefficient (`lidarjax.sensitivity.budget_columns`), with the run's metadata;
- ``budget.png``: the budget bars per height of the rotation with the largest uncertainty
  of the first output, and ``sensitivity_profiles.png``: the sensitivity coefficients
  against z/H over the rotations (with ``plots=True`` and matplotlib installed).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from .. import scan as scans
from .._util import PathLike, have_module
from ..field import AbstractField
from ..io.fields import load_field
from ..io.seed_output import write_table_csv
from ..io.settings import Settings, read_settings
from ..plots import plot_budget, plot_sensitivity_profiles
from ..probe import AbstractProbe
from ..scan import Scan
from ..sensitivity import OUTPUTS, Budget, budget_columns, uncertainty
from .seed_tables import SEED_U_REF, ExactPoints, settings_mount

__all__ = ["SensitivityReport", "sensitivity_report", "write_sensitivity_report",
           "REPORT_OUTPUTS", "REPORT_SCANS"]

#: The outputs `sensitivity_report` budgets by default.
REPORT_OUTPUTS = ("lidar_speed", "lidar_direction", "cff_U", "cff_th")
#: The scans `sensitivity_report` builds by name.
REPORT_SCANS = ("windcube_v1", "windcube_v2", "zephir")
#: Outputs without one value per height (not budgeted per height).
_NOT_PER_HEIGHT = ("los", "lidar_velocity", "inv_speed", "inv_direction")
_METHOD = "GUM law of propagation u^2 = J C J^T with exact forward-mode Jacobians"


@dataclasses.dataclass(frozen=True, eq=False)
class SensitivityReport:
    """What `sensitivity_report` found (``s`` platform rotations, ``h`` heights).

    - `betas`: ``(s,)`` the platform rotations, degrees.
    - `budget`: the `lidarjax.Budget` of every rotation (host numpy; leading axis ``s``).
    - `outputs`: the budgeted outputs; `std`: the inputs' standard uncertainties as given.
    - `z_over_h`: ``(s, h)`` (lidar z + height) / `ref_height`; `lidar_z`: ``(s,)`` m.
    - `scan`, `scan_name`, `probe`, `pitch`, `roll` (degrees), `u_ref` (CFD frame, m/s).
    """

    betas: tuple[float, ...]
    budget: Budget
    outputs: tuple[str, ...]
    std: dict
    z_over_h: np.ndarray
    lidar_z: np.ndarray
    ref_height: float
    scan: Scan
    scan_name: str
    probe: AbstractProbe | None
    pitch: float
    roll: float
    u_ref: tuple[float, ...]

    @property
    def largest(self) -> dict[str, float]:
        """The largest standard uncertainty of each output over rotations and heights."""
        return {o: float(np.nanmax(self.budget.std[o])) for o in self.outputs}

    @property
    def worst_rotation(self) -> int:
        """Index of the rotation with the largest uncertainty of the first output."""
        return int(np.nanargmax(np.nanmax(self.budget.std[self.outputs[0]], axis=-1)))

    def metadata(self) -> dict:
        """The report's configuration as CSV metadata."""
        return {"scan": self.scan_name,
                "probe": "point" if self.probe is None else type(self.probe).__name__,
                "std": ";".join(f"{k}={v}" for k, v in self.std.items()),
                "pitch_deg": self.pitch, "roll_deg": self.roll,
                "tilt_compensation": bool(self.scan.tilt_compensation),
                "ref_height_m": self.ref_height,
                "u_ref_cfd_m_s": ",".join(map(str, self.u_ref)),
                "method": _METHOD}


def _fields(fields, betas: list[float], points: list[ExactPoints]) -> list[AbstractField]:
    def load(f, k):
        # a mesh (OpenFOAM case, VTK file) exact, its own cellPoint, at every point the
        # rotation samples (`ExactPoints`); the graded grid serves only the Monte Carlo's
        # perturbed points
        return load_field(f, exact_at=points[k]) if isinstance(f, str | Path) else f

    if isinstance(fields, AbstractField):
        return [fields] * len(betas)
    if isinstance(fields, Mapping):
        missing = [b for b in betas if b not in fields]
        if missing:
            raise ValueError(f"sensitivity_report: no field for beta {missing[0]:g}")
        return [load(fields[b], k) for k, b in enumerate(betas)]
    if callable(fields):
        return [load(fields(b), k) for k, b in enumerate(betas)]
    fields = list(fields)
    if len(fields) != len(betas):
        raise ValueError(f"sensitivity_report: {len(fields)} fields for {len(betas)} betas")
    return [load(f, k) for k, f in enumerate(fields)]


def sensitivity_report(
    settings: Settings | PathLike,
    fields: AbstractField | Mapping[float, AbstractField | PathLike]
    | Sequence[AbstractField | PathLike] | Callable[[float], AbstractField],
    *,
    std: Mapping[str, float | Sequence[float]],
    betas: Sequence[float] | None = None,
    scan: str | Scan = "windcube_v2",
    cone_angle: float | None = None,
    tilt_compensation: bool = False,
    probe: AbstractProbe | None = None,
    u_ref: Sequence[float] = SEED_U_REF,
    outputs: Sequence[str] = REPORT_OUTPUTS,
    pitch: float = 0.0,
    roll: float = 0.0,
    n_monte_carlo: int = 0,
    ref_height: float | None = None,
) -> SensitivityReport:
    """Uncertainty budgets of a settings.dat's lidar for every platform rotation, one batch.

    **Arguments:**

    - `settings`: a `lidarjax.io.Settings` or the path of a settings.dat.
    - `fields`: the CFD run of each rotation: a sequence in the order of `betas`, a mapping
      ``{beta: field}``, a function of beta, or one field for all; paths are read with
      `lidarjax.io.load_field`, a mesh (OpenFOAM case, VTK file) exact at every point its
      rotation samples (`lidarjax.ExactPoints`: the mesh's own
      cellPoint there; the graded grid answers only the Monte Carlo's perturbed points).
    - `std`: ``{input: standard uncertainty}`` in the input's unit (`lidarjax.uncertainty`),
      e.g. ``{"epsilon": 0.5, "pitch": 0.2, "location": (0.05, 0.05, 0.1)}``.
    - `betas`: the rotations (degrees; default every row of the settings).
    - `scan`: a name of `REPORT_SCANS` (with `cone_angle` in degrees and
      `tilt_compensation`) or a `lidarjax.Scan`.
    - `probe`: the probe volume (default point); `u_ref`: the free stream in the CFD frame,
      m/s (default the seed UDF's); `outputs`: per-height outputs (`REPORT_OUTPUTS`).
    - `pitch`, `roll`: the installation's nominal tilt, degrees.
    - `n_monte_carlo`: 0, or at least 2 samples per rotation to check the linear budget.
    - `ref_height`: H of z/H in metres (default: the lidars' mean z; the settings' height
      where that is not positive).

    **Returns:** a `SensitivityReport`. Raises `ValueError` for unknown outputs, a Monte
    Carlo of one sample, a non-positive reference height or non-finite angles.
    """

    outputs = tuple(outputs)
    bad = [o for o in outputs if o not in OUTPUTS or o in _NOT_PER_HEIGHT]
    if bad or not outputs:
        raise ValueError(f"sensitivity_report: unknown or not per-height output(s) {bad}")
    if n_monte_carlo < 0 or n_monte_carlo == 1:
        raise ValueError(f"sensitivity_report: n_monte_carlo must be 0 or at least 2, got "
                         f"{n_monte_carlo}")
    if ref_height is not None and not ref_height > 0:
        raise ValueError(f"sensitivity_report: ref_height must be positive (m), got {ref_height}")
    for name, v in (("pitch", pitch), ("roll", roll)):
        if not np.isfinite(v):
            raise ValueError(f"sensitivity_report: {name} must be a finite angle in degrees, "
                             f"got {v}")
    if not isinstance(settings, Settings):
        settings = read_settings(settings)
    betas = [float(b) for b in (settings.betas if betas is None else betas)]
    if isinstance(scan, Scan):
        if cone_angle is not None or tilt_compensation:
            raise ValueError("sensitivity_report: cone_angle and tilt_compensation apply to a "
                             "scan given by name")
        scan_name = scan.method
    else:
        if scan not in REPORT_SCANS:
            raise ValueError(f"sensitivity_report: unknown scan {scan!r}; choose from "
                             f"{REPORT_SCANS}")
        make, scan_name = getattr(scans, scan), scan
        kw = {"tilt_compensation": bool(tilt_compensation)}
        scan = make(**kw) if cone_angle is None else make(cone_angle, **kw)
    mounts = settings_mount(settings, betas, pitch=pitch, roll=roll)
    heights = jnp.asarray(settings.heights())
    runs = _fields(fields, betas, [ExactPoints(scan, mounts[k], heights, probe)
                                   for k in range(len(betas))])
    budget = uncertainty(runs, scan, mounts, heights, std=std, u_ref=u_ref, probe=probe,
                         outputs=outputs, n_monte_carlo=n_monte_carlo)
    budget = jax.tree_util.tree_map(np.asarray, budget)
    lidar_z = np.array([float(settings.location(b)[2]) for b in betas])
    ref = ref_height if ref_height is not None else float(np.mean(lidar_z))
    if not ref > 0:
        ref = float(settings.height)
    z_over_h = (lidar_z[:, None] + np.asarray(budget.heights)[None]) / ref
    return SensitivityReport(
        betas=tuple(betas), budget=budget, outputs=outputs, std=dict(std), z_over_h=z_over_h,
        lidar_z=lidar_z, ref_height=ref, scan=scan, scan_name=scan_name, probe=probe,
        pitch=pitch, roll=roll, u_ref=tuple(float(u) for u in np.ravel(u_ref)))


def write_sensitivity_report(out: PathLike, report: SensitivityReport, *, plots: bool = True,
                             metadata: Mapping | None = None) -> list[Path]:
    """Write `report` to the folder `out` (created): one ``budget_<output>.csv`` per output
    and, with ``plots=True`` and matplotlib, ``budget.png`` and ``sensitivity_profiles.png``
    (module docs). `metadata` (e.g. the input files) comes first in each CSV's metadata and
    overrides the report's own (`SensitivityReport.metadata`).

    **Returns:** the paths written, in order."""

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    meta = dict(metadata or {})
    for key, value in report.metadata().items():
        meta.setdefault(key, value)
    budget, outputs, betas, z_over_h = report.budget, report.outputs, report.betas, report.z_over_h
    written = []
    for o in outputs:
        cols, units = budget_columns(budget, o, betas, z_over_h)
        written.append(write_table_csv(out / f"budget_{o}.csv", cols, units, meta))
    if plots and have_module("matplotlib"):
        k = report.worst_rotation
        written.append(plot_budget(
            z_over_h[k], budget.inputs, {o: budget.contribution[o][k] for o in outputs},
            {o: budget.std[o][k] for o in outputs}, {o: OUTPUTS[o] for o in outputs},
            out / "budget.png",
            title=f"uncertainty budget, beta = {betas[k]:g} deg (largest u({outputs[0]}))"))
        written.append(plot_sensitivity_profiles(
            z_over_h.mean(0), budget.inputs, {o: budget.jacobian[o] for o in outputs},
            {(o, n): f"{OUTPUTS[o]} per {u}" for o in outputs
             for n, u in zip(budget.inputs, budget.input_units, strict=True)},
            out / "sensitivity_profiles.png",
            title=f"sensitivity profiles over {len(betas)} platform rotations"))
    return written
