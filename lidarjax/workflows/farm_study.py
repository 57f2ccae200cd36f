"""A lidar among wind turbines, swept over inflow directions: wakes, correction roses, IEC
disturbed sectors, yaw gradients and CFD monitor points (the job of ``lidarjax farm``).

`farm_study` takes a wind farm (a seed 004 layout read with `lidarjax.io.read_farm`, the
layout and turbine-type files themselves, or a `lidarjax.scenes.WindFarm`) and a ground lidar
(``lidar=(x, y, z)``) or a nacelle lidar on one turbine (``nacelle="T001"``), simulates it for
every inflow direction in one compiled batch (`lidarjax.simulate_rotations`) and returns a
`FarmStudy`: per direction and height the lidar's speed and direction and the correction
factors, the IEC 61400-12-1 Annex A disturbed sectors (`lidarjax.disturbed_sectors`), the
gradient of the reading with respect to every turbine's yaw (exact, `jax.grad`), the
response table and the monitor points of the lidar and the turbines
(`farm_monitor_points`). `write_farm_study` writes them as ``lidarjax farm`` does.

Units and frames:

- positions in metres in the layout's projected (UTM) frame, which is the CFD frame: ``x``
  east, ``y`` north, ``z`` up from the ground datum (absolute coordinates; the farm keeps
  them exact relative to its `origin`);
- wind directions in meteorological degrees (where the wind comes from, clockwise from
  north); yaw in degrees, positive anticlockwise seen from above;
- heights: for a ground lidar, metres above the lidar; for a nacelle lidar, metres along
  its axis ahead of the hub;
- speeds in m/s; ``speed_ratio`` = free stream / lidar (`lidarjax.Simulation.cff_U`),
  ``direction_addend`` = free stream minus lidar direction, degrees (``cff_th``).

`write_farm_study` writes to a folder:

- ``roses.png``: correction roses with the disturbed sectors shaded (matplotlib);
- ``map.png``: the hub-height wake field at the map direction with turbines, lidar, beams;
- ``directions.csv``: per direction, disturbed or not, lidar speed/direction, correction
  factors (and the nacelle lidar's yaw misalignment) per height;
- ``yaw_gradient.csv``: d(lidar speed at the first height)/d(yaw) of every turbine, m/s per
  degree, per direction (0 for turbines whose wake misses the beams);
- ``sectors.csv``: each turbine's bearing, distance and excluded width; the merged sectors;
- ``probes.csv``, ``lidarProbes`` (OpenFOAM ``probes`` dictionary), ``lidarProbes_zcfd.py``
  (zCFD ``turb_probe``, seed 004): the `FarmStudy.monitor_points`;
- ``table.npz``: the response table (for ``lidarjax correct``; three directions or more).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import scan as scans
from .._util import PathLike, atomic_write_text
from ..angles import heading
from ..batch import simulate_rotations
from ..disturbed_sectors import DisturbedSector, disturbed_sectors, in_sectors, merge_sectors
from ..forward import Simulation, simulate
from ..io.layout import FarmLayout, read_farm
from ..io.monitor_points import (
    MonitorPoints,
    write_monitor_points_csv,
    write_openfoam_probes,
    write_zcfd_probes,
)
from ..io.tables import save_table
from ..mount import Mount
from ..plots import plot_farm_map, plot_roses
from ..probe import AbstractProbe, CWProbe, PulsedProbe
from ..response import ResponseTable
from ..scan import Scan
from ..scenes.farm import WindFarm, nacelle_mount
from .monitor_points import monitor_points

__all__ = ["FarmStudy", "FarmStudyConfig", "farm_study", "write_farm_study", "farm_monitor_points",
           "check_lidar_position", "FARM_SCANS"]

#: The scans `farm_study` builds by name (ground lidars, then nacelle lidars).
FARM_SCANS = ("windcube_v1", "windcube_v2", "zephir", "nacelle_2beam", "nacelle_4beam")

_MONITOR_ROWS = ("lidar beam points (quadrature nodes with --probe pulsed/cw), then turbine hub "
                 "centres and seed 004 reference points 1 D upstream at hub height (beam/node -3)")


@dataclasses.dataclass(frozen=True, eq=False)
class FarmStudy:
    """What `farm_study` found (``d`` directions, ``h`` heights, ``i`` turbines).

    **Results** (host numpy, float64):

    - `lidar_speed`, `lidar_direction`: ``(d, h)`` the lidar's horizontal speed (m/s) and
      direction (degrees; a ground lidar reports meteorological directions, a nacelle
      lidar true directions since its mount has ``north=True``).
    - `speed_ratio`, `direction_addend`: ``(d, h)`` free stream / lidar and free stream
      minus lidar (degrees): the correction factors ``cff_U`` and ``cff_th``.
    - `yaw_misalignment`: ``(d, h)`` a nacelle lidar's reported direction minus the bearing
      its axis points to, wrapped to [-180, 180) degrees; None for a ground lidar.
    - `disturbed`: ``(d,)`` whether each direction lies in a merged disturbed sector.
    - `sectors`: every other turbine's `lidarjax.DisturbedSector` seen from the lidar;
      `merged_sectors`: their union, ``(start, end)`` degrees (`lidarjax.merge_sectors`).
    - `yaw_gradient`: ``(d, i)`` d(lidar speed at the first height)/d(yaw of each turbine),
      m/s per degree (exactly 0 for turbines whose wake misses the beams).
    - `table`: the `lidarjax.ResponseTable` over the directions (None below 3 directions).
    - `monitor_points`: `farm_monitor_points` at the map direction.
    - `simulations`: the `lidarjax.Simulation` of every direction (leading axis ``d``).

    **The map** (the direction with the largest speed correction unless given):
    `map_direction` (degrees), `map_index` (its row in `directions`, or None when
    `map_direction` was given), `map_farm` (the `WindFarm` from that direction),
    `map_lidar` ``(2,)`` and `map_beams` ``(b, 2, 2)`` (lidar and beam segments at the top
    height, horizontal coordinates relative to the farm's origin, m).

    **Configuration:** `names`, `directions` ``(d,)``, `heights` ``(h,)``, `farm` (at the
    first direction), `scan`, `scan_name`, `probe`, `nacelle` (turbine name or None),
    `backward`, `lidar_location` ``(3,)`` (absolute m; a nacelle lidar's hub), `speed`
    (free stream at hub height, m/s), `shear`, `model`, `combination`, `yaw` ``(i,)``
    (degrees), `hub_height` ``(i,)`` (m) and `layouts` (the layout files read, as given).
    """

    names: tuple[str, ...]
    directions: np.ndarray
    heights: np.ndarray
    lidar_speed: np.ndarray
    lidar_direction: np.ndarray
    speed_ratio: np.ndarray
    direction_addend: np.ndarray
    yaw_misalignment: np.ndarray | None
    disturbed: np.ndarray
    sectors: tuple[DisturbedSector, ...]
    merged_sectors: tuple[tuple[float, float], ...]
    yaw_gradient: np.ndarray
    table: ResponseTable | None
    monitor_points: MonitorPoints
    simulations: Simulation
    map_direction: float
    map_index: int | None
    map_farm: WindFarm
    map_lidar: np.ndarray
    map_beams: np.ndarray
    farm: WindFarm
    scan: Scan
    scan_name: str
    probe: AbstractProbe | None
    nacelle: str | None
    backward: bool
    lidar_location: np.ndarray
    speed: float
    shear: float
    model: str
    combination: str
    yaw: np.ndarray
    hub_height: np.ndarray
    layouts: tuple[str, ...]

    @property
    def kind(self) -> str:
        """``"ground lidar"`` or ``"nacelle lidar on <name>"``."""
        return f"nacelle lidar on {self.nacelle}" if self.nacelle is not None else "ground lidar"

    @property
    def largest_correction(self) -> float:
        """The largest ``|speed_ratio - 1|`` over directions and heights."""
        return float(np.nanmax(np.abs(self.speed_ratio - 1)))


# ----------------------------------------------------------------------------- checks
def check_lidar_position(layout: FarmLayout, location) -> None:
    """Raise `ValueError` when a ground lidar at `location` ``(x, y, z)`` (absolute m; z above
    the ground datum) stands inside a turbine's rotor or under it (its beams would cross the
    blades), naming the turbine."""

    xyz = [float(v) for v in location]
    d = np.hypot(layout.easting - xyz[0], layout.northing - xyz[1])
    r = 0.5 * layout.diameter
    inside = (d < r) & (xyz[2] > layout.hub_height - r - 1e-9) & (xyz[2] < layout.hub_height + r)
    inside |= d < 0.5  # standing on the tower
    if inside.any():
        k = int(np.argmax(inside))
        raise ValueError(f"the lidar at ({xyz[0]:g}, {xyz[1]:g}, {xyz[2]:g}) is inside turbine "
                         f"{layout.names[k]}'s rotor ({d[k]:.1f} m from its tower, rotor radius "
                         f"{r[k]:g} m, hub {layout.hub_height[k]:g} m)")
    under = d < r
    if under.any():
        k = int(np.argmax(under))
        raise ValueError(f"the lidar is inside turbine {layout.names[k]}'s rotor footprint "
                         f"({d[k]:.1f} m from its tower, rotor radius {r[k]:g} m): its beams "
                         f"would cross the blades")


def _layout_of(farm: WindFarm, names) -> FarmLayout:
    """A `FarmLayout` view of a `WindFarm` (absolute float64 coordinates)."""
    n = int(farm.x.shape[0])
    names = tuple(f"T{k}" for k in range(n)) if names is None else tuple(str(x) for x in names)
    if len(names) != n:
        raise ValueError(f"farm_study: {len(names)} names for {n} turbines")
    if len(set(names)) != n:
        raise ValueError(f"farm_study: turbine names must be unique, got {list(names)}")
    origin = np.asarray(farm.origin, np.float64) + np.asarray(farm.origin_lo, np.float64)
    return FarmLayout(names=names, easting=np.asarray(farm.x, np.float64) + origin[0],
                      northing=np.asarray(farm.y, np.float64) + origin[1],
                      diameter=np.asarray(farm.diameter, np.float64),
                      hub_height=np.asarray(farm.hub_height, np.float64), types=(),
                      type_index=np.zeros(n, int))


def _yaw_vector(yaw, names) -> np.ndarray:
    out = np.zeros(len(names))
    if yaw is None:
        return out
    if isinstance(yaw, Mapping):
        for name, value in yaw.items():
            if name not in names:
                raise ValueError(f"farm_study: yaw: no turbine named {name!r}")
            out[names.index(name)] = float(value)
    else:
        values = np.asarray(yaw, np.float64)
        if values.shape not in ((), (len(names),)):
            raise ValueError(f"farm_study: yaw must be one value, one per turbine "
                             f"({len(names)}) or a mapping name -> degrees")
        out[:] = values
    if not np.all(np.isfinite(out)) or np.any(np.abs(out) >= 90):
        raise ValueError(f"farm_study: |yaw| must be below 90 degrees, got {out.tolist()}")
    return out


def _probe(probe) -> AbstractProbe | None:
    if probe is None or isinstance(probe, AbstractProbe):
        return probe
    choices = {"point": None, "pulsed": PulsedProbe, "cw": CWProbe}
    if probe not in choices:
        raise ValueError(f"farm_study: probe must be a lidarjax probe, None or one of "
                         f"{list(choices)}, got {probe!r}")
    return None if choices[probe] is None else choices[probe]()


def _scan(scan, cone_angle, nacelle: bool) -> tuple[Scan, str]:
    if isinstance(scan, Scan):
        if cone_angle is not None:
            raise ValueError("farm_study: cone_angle applies to a scan given by name")
        name = scan.method
    else:
        name = scan or ("nacelle_2beam" if nacelle else "windcube_v2")
        if name not in FARM_SCANS:
            raise ValueError(f"farm_study: unknown scan {name!r}; choose from {FARM_SCANS}")
        make = getattr(scans, name)
        scan = make() if cone_angle is None else make(cone_angle)
    if nacelle != name.startswith("nacelle"):
        raise ValueError(f"farm_study: the scan {name} is a {'ground' if nacelle else 'nacelle'} "
                         f"lidar's, but the lidar is {'a nacelle' if nacelle else 'a ground'} "
                         f"lidar; use {'a nacelle_* scan' if nacelle else 'nacelle=NAME'}")
    return scan, name


# ------------------------------------------------------------------------------ study
@dataclasses.dataclass(frozen=True)
class FarmStudyConfig:
    """What `farm_study` simulates besides the farm: the lidar, its scan and heights, the
    directions, the wake model and the probe. Every field has a default except the lidar
    (`lidar` or `nacelle`, exactly one).

    - `lidar`: a ground lidar's ``(x, y, z)``, absolute metres (z above the ground datum);
      or `nacelle`: the name of the turbine carrying a nacelle lidar (at its hub, yawed with
      it, looking upstream; ``backward=True`` looks downstream into its own wake).
    - `scan`: a name of `FARM_SCANS` (default ``windcube_v2`` on the ground,
      ``nacelle_2beam`` on a nacelle; `cone_angle` in degrees overrides the scan's cone or
      half-angle) or a `lidarjax.Scan`.
    - `heights`: metres above a ground lidar (default: the mean hub height) or along a
      nacelle lidar's axis (default 2.5 rotor diameters).
    - `directions`: inflow directions, meteorological degrees (default every 2 degrees),
      distinct modulo 360.
    - `speed` (free stream at hub height, m/s, default 10), `shear` (power-law exponent,
      default 0), `model` (``"gaussian"``, default, or ``"top_hat"``), `combination`
      (``"sum_of_squares"``, default, ``"linear"`` or ``"max"``), `expansion` (wake
      expansion k; default the model's): the wake model (`lidarjax.scenes.wind_farm`), for a
      farm given as a layout (a `lidarjax.scenes.WindFarm` carries its own).
    - `yaw`: yaw misalignments in degrees, ``{name: degrees}`` or one per turbine (layouts
      only, like the wake model).
    - `probe`: ``"pulsed"`` (default), ``"cw"``, ``"point"`` / None, or a probe.
    - `map_direction`: the direction of the map and of the monitor points (default: the
      direction with the largest speed correction at the first height).
    - `names`: the turbines' names of a `WindFarm` (default ``T0``, ``T1``, ...).
    """

    lidar: Sequence[float] | None = None
    nacelle: str | None = None
    backward: bool = False
    scan: str | Scan | None = None
    cone_angle: float | None = None
    heights: Sequence[float] | None = None
    directions: Sequence[float] = tuple(range(0, 360, 2))
    speed: float | None = None
    shear: float | None = None
    model: str | None = None
    combination: str | None = None
    expansion: float | None = None
    yaw: Mapping[str, float] | Sequence[float] | None = None
    probe: AbstractProbe | str | None = "pulsed"
    map_direction: float | None = None
    names: Sequence[str] | None = None


def farm_study(
    farm: WindFarm | FarmLayout | PathLike | Sequence[PathLike],
    turbines: PathLike | Sequence[PathLike] | None = None,
    config: FarmStudyConfig | None = None,
    **options,
) -> FarmStudy:
    """Simulate a lidar in a wind farm's wakes for every inflow direction.

    **Arguments:**

    - `farm`: a `lidarjax.io.FarmLayout` (`lidarjax.io.read_farm`), the path(s) of seed 004
      layout files (then `turbines` gives the turbine type file(s): one for all or one per
      layout), or a `lidarjax.scenes.WindFarm` (then its speed, shear, wake model,
      combination, expansion and yaw are used; `names` names its turbines).
    - `config`: a `FarmStudyConfig` (the lidar, scan, heights, directions, wake model,
      probe and map direction; units there).
    - `options`: `FarmStudyConfig` fields given as keywords (``lidar=(x, y, z)``,
      ``nacelle="T001"``, ``directions=...``, ...); they replace those of `config`.

    **Returns:** a `FarmStudy`. Raises `ValueError` (one line) for a lidar inside or under a
    rotor (`check_lidar_position`), unknown turbine names, a scan of the other kind of lidar,
    or non-positive speeds and heights.
    """

    cfg = dataclasses.replace(config or FarmStudyConfig(), **options)
    lay, layouts, base = _resolved_farm(farm, turbines, cfg)
    plan = _plan(lay, base, cfg)
    farm, plan = _farm_at(lay, base, plan)
    sims_all, grad_yaw = _sweep(farm, plan)
    sims = jax.tree_util.tree_map(lambda a: a[: plan.dirs.size], sims_all)
    origin = np.asarray(farm.origin, np.float64) + np.asarray(farm.origin_lo, np.float64)
    ratio = np.asarray(sims.cff_U, np.float64)
    ldir = np.asarray(sims.lidar_direction, np.float64)
    misalignment = None
    if plan.k_nac is not None:
        # a nacelle lidar reports (north=True) true directions; its yaw misalignment is the
        # reported direction minus the bearing its axis points to (rotor heading, +180 backward)
        axis = plan.dirs - plan.yaw_deg[plan.k_nac] + (180.0 if plan.backward else 0.0)
        misalignment = np.mod(ldir - axis[:, None] + 180.0, 360.0) - 180.0
        location = np.asarray(farm.hub_points()[plan.k_nac], np.float64) + origin
    else:
        location = plan.lidar
    secs = disturbed_sectors(location[:2], lay.easting, lay.northing, lay.diameter,
                             plan.names)
    merged = merge_sectors(secs)
    k_map = int(np.nanargmax(np.abs(ratio[:, 0] - 1.0))) if cfg.map_direction is None else None
    map_dir = float(plan.dirs[k_map]) if k_map is not None else float(cfg.map_direction)
    f_map, m_map = _farm_and_mount(farm, plan, map_dir)
    pts_abs = np.asarray(sims_all.points[k_map if k_map is not None else -1], np.float64)
    m_loc = np.asarray(m_map.location, np.float64) + np.asarray(m_map.location_lo, np.float64)
    lidar_local = m_loc - origin
    beams = np.stack([np.broadcast_to(lidar_local[:2], pts_abs[-1, :, :2].shape),
                      pts_abs[-1, :, :2] - origin[:2]], 1)
    points = farm_monitor_points(f_map, plan.scan, m_map, plan.heights, plan.probe,
                                 names=plan.names)
    table = (ResponseTable.from_simulations(sims, mount=None, scan=plan.scan, probe=plan.probe)
             if plan.dirs.size >= 3 else None)
    return FarmStudy(
        names=tuple(plan.names), directions=plan.dirs,
        heights=np.asarray(plan.heights, np.float64),
        lidar_speed=np.asarray(sims.lidar_speed, np.float64), lidar_direction=ldir,
        speed_ratio=ratio, direction_addend=np.asarray(sims.cff_th, np.float64),
        yaw_misalignment=misalignment, disturbed=np.asarray(in_sectors(plan.dirs, merged), bool),
        sectors=tuple(secs), merged_sectors=tuple(merged), yaw_gradient=grad_yaw, table=table,
        monitor_points=points, simulations=sims, map_direction=map_dir, map_index=k_map,
        map_farm=f_map, map_lidar=np.asarray(lidar_local[:2]), map_beams=beams, farm=farm,
        scan=plan.scan, scan_name=plan.scan_name, probe=plan.probe, nacelle=cfg.nacelle,
        backward=bool(plan.backward), lidar_location=location, speed=plan.speed,
        shear=float(plan.shear), model=plan.model, combination=plan.combination,
        yaw=plan.yaw_deg, hub_height=np.asarray(lay.hub_height, np.float64), layouts=layouts)


def _resolved_farm(farm, turbines, cfg: FarmStudyConfig):
    """The farm as a `FarmLayout`, the layout files read (as given) and the `WindFarm` given
    (None for a layout), checking that the options go with the kind of farm given."""
    if isinstance(farm, WindFarm):
        if turbines is not None:
            raise ValueError("farm_study: `turbines` goes with layout files, not a WindFarm")
        given = [k for k in ("speed", "shear", "model", "combination", "expansion", "yaw")
                 if getattr(cfg, k) is not None]
        if given:
            raise ValueError(f"farm_study: {', '.join(given)} configure a farm built from a "
                             "layout; a WindFarm carries its own (change it with "
                             "equinox.tree_at or build it with the values wanted)")
        return _layout_of(farm, cfg.names), (), farm
    if cfg.names is not None:
        raise ValueError("farm_study: `names` goes with a WindFarm; a layout names its "
                         "turbines")
    if isinstance(farm, FarmLayout):
        if turbines is not None:
            raise ValueError("farm_study: `turbines` goes with layout files, not a "
                             "FarmLayout")
        return farm, (), None
    if turbines is None:
        raise ValueError("farm_study: give the turbine type file(s) with `turbines=`")
    paths = [farm] if isinstance(farm, str | Path) else list(farm)
    return read_farm(paths, turbines), tuple(str(p) for p in paths), None


@dataclasses.dataclass(frozen=True)
class _Plan:
    """`farm_study`'s checked configuration: turbine `names`, the nacelle lidar's turbine
    index `k_nac` (None on the ground), the ground `lidar` ``(3,)`` and its mount `ground`,
    `heights`, `dirs`,
    the scan, probe and wake model, and `yaw_deg` ``(i,)``."""

    names: list
    k_nac: int | None
    backward: bool
    lidar: np.ndarray | None
    ground: Mount | None
    scan: Scan
    scan_name: str
    heights: list
    dirs: np.ndarray
    probe: AbstractProbe | None
    yaw_deg: np.ndarray
    speed: float
    shear: float | None
    model: str | None
    combination: str | None
    expansion: float | None
    map_direction: float | None


def _plan(lay: FarmLayout, base: WindFarm | None, cfg: FarmStudyConfig) -> _Plan:
    """Check the configuration against the layout (before compiling anything)."""
    names = list(lay.names)
    speed = 10.0 if cfg.speed is None else cfg.speed
    if base is None and not (speed > 0 and np.isfinite(speed)):
        raise ValueError(f"farm_study: speed must be positive m/s, got {speed}")
    yaw_deg = _yaw_vector(cfg.yaw, names) if base is None else np.asarray(base.yaw, np.float64)
    nacelle, lidar = cfg.nacelle, cfg.lidar
    if (lidar is None) == (nacelle is None):
        raise ValueError("farm_study: give either lidar=(x, y, z) (a ground lidar) or "
                         "nacelle=NAME (a nacelle lidar)")
    is_nacelle = nacelle is not None
    if is_nacelle and nacelle not in names:
        raise ValueError(f"farm_study: no turbine named {nacelle!r} for the nacelle lidar")
    if cfg.backward and not is_nacelle:
        raise ValueError("farm_study: backward=True needs a nacelle lidar")
    scan, scan_name = _scan(cfg.scan, cfg.cone_angle, is_nacelle)
    if not is_nacelle:
        lidar = np.asarray(lidar, np.float64)
        if lidar.shape != (3,) or not np.all(np.isfinite(lidar)):
            raise ValueError(f"farm_study: lidar must be finite (x, y, z) metres, got "
                             f"{lidar.tolist()}")
        check_lidar_position(lay, lidar)
    k_nac = names.index(nacelle) if is_nacelle else None
    heights = cfg.heights
    if heights is None:
        heights = ([2.5 * float(lay.diameter[k_nac])] if is_nacelle
                   else [float(np.mean(lay.hub_height))])
    heights = [float(h) for h in np.atleast_1d(np.asarray(heights, np.float64))]
    if not heights or any(not (h > 0 and np.isfinite(h)) for h in heights):
        raise ValueError(f"farm_study: heights must be positive metres, got {heights}")
    dirs = np.atleast_1d(np.asarray(cfg.directions, np.float64))
    if dirs.ndim != 1 or dirs.size == 0 or not np.all(np.isfinite(dirs)):
        raise ValueError("farm_study: directions must be a non-empty 1-D array of finite "
                         "degrees")
    if np.unique(np.mod(np.round(dirs, 9), 360.0)).size != dirs.size:
        raise ValueError("farm_study: directions repeat modulo 360")
    map_direction = cfg.map_direction
    if map_direction is not None and not np.isfinite(map_direction):
        raise ValueError(f"farm_study: map_direction must be finite degrees, got {map_direction}")
    return _Plan(names=names, k_nac=k_nac, backward=cfg.backward,
                 lidar=None if is_nacelle else lidar,
                 ground=None if is_nacelle else Mount(lidar), scan=scan, scan_name=scan_name,
                 heights=heights, dirs=dirs, probe=_probe(cfg.probe), yaw_deg=yaw_deg,
                 speed=speed, shear=cfg.shear, model=cfg.model, combination=cfg.combination,
                 expansion=cfg.expansion, map_direction=map_direction)


def _farm_at(lay: FarmLayout, base: WindFarm | None, plan: _Plan):
    """The `WindFarm` at the first direction (built from the layout, or the one given) and
    `plan` completed with the wake model it has (speed, shear, model, combination)."""
    dirs = plan.dirs
    if base is None:
        model = plan.model or "gaussian"
        combination = plan.combination or "sum_of_squares"
        shear = 0.0 if plan.shear is None else plan.shear
        farm = lay.to_farm(speed=plan.speed, direction=float(dirs[0]), alpha=shear,
                           model=model, combination=combination, expansion=plan.expansion,
                           yaw=plan.yaw_deg)
        speed = plan.speed
    else:
        farm = eqx.tree_at(lambda g: g.direction, base, jnp.asarray(dirs[0], base.dtype))
        speed, shear = float(base.speed), float(base.alpha)
        model, combination = base.model, base.combination
    return farm, dataclasses.replace(plan, speed=float(speed), shear=shear, model=model,
                                     combination=combination)


def _farm_and_mount(farm: WindFarm, plan: _Plan, direction, yaw_deg=None):
    """The farm turned to `direction` (and yawed to `yaw_deg` when given) and the lidar's
    mount in it (a nacelle lidar's follows its turbine)."""
    f = eqx.tree_at(lambda g: g.direction, farm, jnp.asarray(direction, farm.dtype))
    if yaw_deg is not None:
        f = eqx.tree_at(lambda g: g.yaw, f, yaw_deg)
    if plan.k_nac is not None:
        return f, nacelle_mount(f, plan.k_nac, backward=plan.backward, north=True)
    return f, plan.ground


def _sweep(farm: WindFarm, plan: _Plan):
    """The simulations of every direction (and of the map direction when given, last) in
    one batch, and d(lidar speed at the first height)/d(yaw) ``(d, i)`` by `jax.grad`."""
    dirs, scan, probe = plan.dirs, plan.scan, plan.probe
    hts = jnp.asarray(plan.heights, farm.dtype)

    def reading(direction, yaw_deg):
        f, m = _farm_and_mount(farm, plan, direction, yaw_deg)
        return simulate(f, scan, m, hts, probe=probe, point_reference=False).lidar_speed[0]

    run_dirs = dirs if plan.map_direction is None else np.append(dirs, plan.map_direction)
    stacked = jax.vmap(lambda d: _farm_and_mount(farm, plan, d)[0])(
        jnp.asarray(run_dirs, farm.dtype))
    mounts = jax.vmap(lambda f: nacelle_mount(f, plan.k_nac, backward=plan.backward,
                                              north=True))(stacked) \
        if plan.k_nac is not None else plan.ground
    u_refs = plan.speed * np.stack([np.asarray(heading(d)) for d in run_dirs])
    sims_all = simulate_rotations(stacked, scan, mounts, hts, u_refs=u_refs, probe=probe,
                                  point_reference=False)
    grad_yaw = np.asarray(jax.jit(jax.vmap(jax.grad(reading, argnums=1), in_axes=(0, None)))(
        jnp.asarray(dirs, farm.dtype), farm.yaw), np.float64)
    return sims_all, grad_yaw


def farm_monitor_points(farm: WindFarm, scan: Scan, mount: Mount, heights, probe=None, *,
                        names: Sequence[str] | None = None) -> MonitorPoints:
    """The lidar's sample points and each turbine's hub and reference point as CFD probes.

    The lidar's rows come from `lidarjax.monitor_points` (label ``lidar``:
    ``lidar_h<height>_beam<b>_q<node>``, no point reference); then each turbine's hub centre
    (``<name>_hub``) and seed 004's reference point one rotor diameter upstream at hub height
    for the farm's current `direction` (``<name>_ref1D``, `WindFarm.reference_points`), in
    absolute CFD metres. Turbine rows have ``beam = node = -3``, NaN beta and weight and
    height = the hub height above the ground datum. `names` default ``T0``, ``T1``, ...
    """

    n_t = int(farm.x.shape[0])
    names = [f"T{k}" for k in range(n_t)] if names is None else [str(x) for x in names]
    if len(names) != n_t:
        raise ValueError(f"farm_monitor_points: {len(names)} names for {n_t} turbines")
    origin = np.asarray(farm.origin, np.float64) + np.asarray(farm.origin_lo, np.float64)
    hub = np.asarray(farm.hub_points(), np.float64) + origin
    ref = np.asarray(farm.reference_points(), np.float64) + origin
    lidar = monitor_points(scan, mount, np.asarray(heights, np.float64), probe,
                           labels=["lidar"])
    n = 2 * n_t
    turbines = MonitorPoints(
        names=tuple(f"{x}_hub" for x in names) + tuple(f"{x}_ref1D" for x in names),
        mount=("turbines",) * n, points=np.concatenate([hub, ref]),
        beta=np.full(n, np.nan), height=np.tile(np.asarray(farm.hub_height, np.float64), 2),
        beam=np.full(n, -3), node=np.full(n, -3), weight=np.full(n, np.nan))
    both = {f: (getattr(lidar, f) + getattr(turbines, f)) if f in ("names", "mount")
            else np.concatenate([getattr(lidar, f), getattr(turbines, f)])
            for f in ("names", "mount", "points", "beta", "height", "beam", "node", "weight")}
    return MonitorPoints(**both)


# ----------------------------------------------------------------------------- writer
def _fmt(x) -> str:
    return "" if not np.isfinite(x) else f"{x:.6g}"


def write_farm_study(out: PathLike, study: FarmStudy, *, plots: bool = True) -> dict[str, Path]:
    """Write `study` to the folder `out` (created): the files listed in the module docs
    (``roses.png`` and ``map.png`` only with ``plots=True``; they need matplotlib;
    ``table.npz`` only when the study has a table). Text files are written atomically.

    **Returns:** ``{file name: path}`` of the files written."""

    out = Path(out)
    if out.exists() and not out.is_dir():
        raise ValueError(f"write_farm_study: {out} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    written: dict[str, Path] = {}
    heights = study.heights
    nacelle = study.nacelle is not None
    kind = study.kind
    if plots:
        labels = [f"{h:g} m" for h in heights]
        written["roses.png"] = plot_roses(
            study.directions, study.speed_ratio, study.direction_addend, labels,
            out / "roses.png", shade=list(study.merged_sectors),
            title=f"{study.scan_name} {kind}, {study.model} wakes, {study.speed:g} m/s")
        written["map.png"] = plot_farm_map(
            study.map_farm, float(np.mean(study.hub_height)), out / "map.png",
            names=list(study.names), lidar=study.map_lidar, beams=study.map_beams,
            title=f"{study.model} wakes from {study.map_direction:g} deg at hub height, {kind}")

    head = ["direction_deg", "disturbed"]
    for h in heights:
        head += [f"lidar_speed_{h:g}m", f"lidar_direction_{h:g}m", f"speed_ratio_{h:g}m",
                 f"direction_addend_{h:g}m"] + ([f"yaw_misalignment_{h:g}m"] if nacelle else [])
    rows = [",".join(head)]
    for i, d in enumerate(study.directions):
        row = [f"{d:g}", str(int(study.disturbed[i]))]
        for j in range(len(heights)):
            row += [_fmt(study.lidar_speed[i, j]), _fmt(study.lidar_direction[i, j]),
                    _fmt(study.speed_ratio[i, j]), _fmt(study.direction_addend[i, j])]
            if nacelle:
                row.append(_fmt(float(study.yaw_misalignment[i, j])))
        rows.append(",".join(row))
    meta = (f"# lidarjax farm: {kind} ({study.scan_name}), {study.model} wakes, "
            f"{study.combination}, free stream {study.speed:g} m/s at hub height, shear "
            f"{study.shear:g}; speed_ratio = free / lidar, direction_addend = free - lidar "
            f"(deg); disturbed: IEC 61400-12-1 A\n")
    written["directions.csv"] = atomic_write_text(out / "directions.csv",
                                                  meta + "\n".join(rows) + "\n")

    rows = ["direction_deg," + ",".join(study.names)]
    rows += [f"{d:g}," + ",".join(f"{g:.6g}" for g in study.yaw_gradient[i])
             for i, d in enumerate(study.directions)]
    written["yaw_gradient.csv"] = atomic_write_text(
        out / "yaw_gradient.csv",
        f"# d(lidar speed at {heights[0]:g} m)/d(yaw of each turbine), m/s per degree (yaw "
        f"positive anticlockwise seen from above)\n" + "\n".join(rows) + "\n")

    rows = ["name,bearing_deg,distance_m,diameter_m,excluded_width_deg,considered,too_close"]
    rows += [f"{s.name},{s.bearing:.3f},{s.distance:.2f},{s.diameter:g},{s.width:.3f},"
             f"{int(s.considered)},{int(s.too_close)}" for s in study.sectors]
    rows += ["", "merged_start_deg,merged_end_deg"]
    rows += [f"{a:.3f},{b:.3f}" for a, b in study.merged_sectors]
    written["sectors.csv"] = atomic_write_text(out / "sectors.csv", "\n".join(rows) + "\n")

    meta = {"direction_deg": study.map_direction, "rows": _MONITOR_ROWS}
    locs = study.monitor_points
    written["probes.csv"] = write_monitor_points_csv(out / "probes.csv", locs, metadata=meta)
    written["lidarProbes"] = write_openfoam_probes(out / "lidarProbes", locs, metadata=meta)
    written["lidarProbes_zcfd.py"] = write_zcfd_probes(out / "lidarProbes_zcfd.py", locs,
                                                       metadata=meta)
    if study.table is not None:
        written["table.npz"] = save_table(
            out / "table.npz", study.table,
            {"scan": study.scan_name, "layouts": list(study.layouts), "model": study.model,
             "speed": study.speed})
    return written
