"""Calibration campaigns written by `lidarjax.simulate` itself, in flows that vary in space.

The generator of tests/_campaign.py is a flow that depends on the direction only, so a tilt
that moves the measurement points changes nothing there. Here the records come from
`lidarjax.simulate` with the truly tilted and turned `lidarjax.Mount` (``pitch``, ``roll``,
and ``gamma`` for the north offset): every beam turns *and its measurement points move*, as a
real lidar's do, in fields with shear, a ridge, a platform and a CFD case. The tables come
from `simulate` at the nominal (level, unturned) installation. Nothing here uses
`lidarjax.calibrate`'s model: its first-order tilt term, direction shift or any gradient.

Settings (`SETTINGS`), all a Windcube V2 (`lidarjax.windcube_v2`, point probe):

- ``uniform`` (the control, not in `SETTINGS`): a uniform wind, where moving a measurement
  point changes nothing (`lidarjax.calibrate`'s model is exact there to first order).

- ``power_law``: shear ``alpha = 0.2`` over flat ground (`lidarjax.scenes.power_law`),
  lidar on the ground, heights 40/80/120 m.
- ``hill_crest``, ``hill_flank``: `lidarjax.scenes.hill` (H = 40 m, half width 200 m, ridge
  normal east-west), the lidar on the crest and 150 m beside it on the slope, 40/80/120 m.
- ``hemisphere``: `lidarjax.scenes.hemisphere` (radius 20 m), the lidar on its roof at
  (4, 3, 20.1) as in the README, heights 10/30/60 m.
- ``openfoam``: the committed OpenFOAM ``turbineSiting`` cut (tests/data/openfoam, a
  converged simpleFoam run over terrain, 10 m/s at 20 m, inflow along +x), the ``hill``
  lidar on its slope, 40/80/120 m, read with `lidarjax.io.load_field` cropped to
  `lidarjax.scan_bounds` of every orientation. One CFD run has one inflow: the direction is
  varied by turning the platform (`Mount.beta`), as `lidarjax.simulate_rotations` does for a
  table, and the speed by scaling (a converged RANS field at one Reynolds number).

Conventions of the truth returned, in the table's north frame (nominal mount: ``psi = beta =
gamma = epsilon = 0``, so the north frame is the CFD frame):

- ``offsets[:, 0]``: the north offset in `lidarjax.calibrate`'s sense, ``epsilon_true -
  epsilon_table``. A lidar turned by ``gamma`` (anticlockwise seen from above) while its
  software keeps ``epsilon = 0`` needs ``epsilon = -gamma`` to report true north (its chain
  is ``R(-epsilon) R(-gamma)``), so the truth is ``-gamma``.
- ``offsets[:, 1:]``: pitch and roll of the `Mount` (degrees).
- ``ref_speed``, ``ref_direction`` ``(c, n, h)``: the free stream (`simulate`'s ``u_ref``) of
  each record, the reference a mast or model would give.

Used by tests/core/test_calibrate_spatial.py and benchmarks/calibration_coverage.py (which
puts the repository root on ``sys.path``).
"""

from __future__ import annotations

import dataclasses
import functools
from collections.abc import Callable
from functools import cache
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

import lidarjax as lj

SCAN = lj.windcube_v2()
OPENFOAM_CASE = Path(__file__).resolve().parent / "data" / "openfoam" / "turbineSiting_cut"
#: The turbineSiting run's free stream: ``Uref = 10`` m/s along +x (from 270 degrees).
OPENFOAM_INFLOW = np.array([10.0, 0.0, 0.0])
#: The ``hill`` lidar of tests/data/openfoam/turbineSiting_points.csv (1 m above terrain).
OPENFOAM_LIDAR = np.array([581700.0, 4786000.0, 994.3090 - 12.0])


@dataclasses.dataclass(frozen=True, eq=False)
class Setting:
    """One site: where the lidar stands, its heights, and the flow.

    `scene(speed, direction)` gives the analytic field for a free stream of `speed` m/s from
    meteorological `direction` degrees (traceable: vmapped over records); for a CFD case
    `scene` is None and `field` is the one run (inflow `inflow`, CFD m/s), turned by the
    platform angle `beta`.
    """

    name: str
    location: np.ndarray
    heights: np.ndarray
    scene: Callable | None = None
    field: object = None
    inflow: np.ndarray | None = None

    @property
    def cfd(self) -> bool:
        return self.scene is None


def _flow(setting: Setting, speed, direction):
    """(field, beta, u_ref, los scale) of a free stream of `speed` m/s from `direction`
    (degrees, north frame of the nominal mount); traceable."""
    if not setting.cfd:
        return setting.scene(speed, direction), 0.0, speed * lj.heading(direction), 1.0
    u = jnp.asarray(setting.inflow)
    d_cfd = lj.wind_direction(u)
    norm = lj.horizontal_speed(u)
    # v_north = R(-beta) v_cfd: turning the platform by beta adds beta to every bearing
    beta = direction - d_cfd
    return setting.field, beta, u, speed / norm


def _one_los(setting: Setting, speed, direction, gamma, pitch, roll):
    field, beta, u, scale = _flow(setting, speed, direction)
    mount = lj.Mount(setting.location, beta=beta, gamma=gamma, pitch=pitch, roll=roll)
    return scale * lj.simulate(field, SCAN, mount, setting.heights, u_ref=u,
                               point_reference=False).los


@cache
def _los_program(setting: Setting):
    """One compiled program per setting: LOS ``(c, n, h, b)`` of ``c`` campaigns of ``n``
    records (speed and direction ``(c, n)``, gamma/pitch/roll ``(c,)``)."""
    rec = jax.vmap(lambda s, d, g, p, r: _one_los(setting, s, d, g, p, r),
                   in_axes=(0, 0, None, None, None))
    return jax.jit(jax.vmap(rec, in_axes=(0, 0, 0, 0, 0)))


def simulate_los(setting: Setting, speed, direction, gamma, pitch, roll) -> np.ndarray:
    """Noise-free LOS ``(c, n, h, b)`` (m/s) of ``c`` campaigns of ``n`` records each, the
    lidar turned by `gamma` and tilted by `pitch`, `roll` (``(c,)``, degrees) and the free
    stream of each record `speed`, `direction` ``(c, n)``."""
    f = lambda a: jnp.asarray(a, jnp.float64)  # noqa: E731
    return np.asarray(_los_program(setting)(f(speed), f(direction), f(gamma), f(pitch),
                                            f(roll)))


# ------------------------------------------------------------------------------------------
# the sites


def _uniform(speed, direction):
    return lj.scenes.uniform(speed=speed, direction=direction)


def _power_law(speed, direction):
    return lj.scenes.power_law(speed_ref=speed, z_ref=100.0, alpha=0.2, direction=direction)


def _hill(speed, direction):
    return lj.scenes.hill(height=40.0, half_width=200.0, speed=speed, direction=direction,
                          ridge_normal=90.0)


def _hemisphere(speed, direction):
    return lj.scenes.hemisphere(radius=20.0, speed=speed, direction=direction)


H3 = np.array([40.0, 80.0, 120.0])
#: Largest tilt and north offset the CFD crop allows for (degrees).
MAX_TILT, MAX_NORTH = 2.0, 10.0


@cache
def _openfoam_field(heights: tuple):
    """The turbineSiting cut resampled on a grid over every beam point any orientation and
    tilt up to `MAX_TILT` (plus a margin) can reach."""
    h = np.asarray(heights)
    mounts = [lj.Mount(OPENFOAM_LIDAR, beta=b, pitch=p, roll=r)
              for b in np.arange(0.0, 360.0, 15.0) for p in (-MAX_TILT - 0.5, MAX_TILT + 0.5)
              for r in (-MAX_TILT - 0.5, MAX_TILT + 0.5)]
    lo, hi = lj.scan_bounds(SCAN, mounts, h, point_reference=False)
    # the graded grid itself is the campaign's field (campaigns and tables sample it through
    # jit and vmap): exact_at=False, not made exact by simulate (issue 37)
    return lj.io.load_field(OPENFOAM_CASE, region=(lo - 8.0, hi + 8.0), exact_at=False)


def setting(name: str, heights=None) -> Setting:
    """The setting `name` of `SETTINGS` (optionally at other `heights`, m)."""
    h = lambda d: np.asarray(d if heights is None else heights, np.float64)  # noqa: E731
    if name == "uniform":
        return Setting(name, np.array([0.0, 0.0, 0.0]), h(H3), _uniform)
    if name == "power_law":
        return Setting(name, np.array([0.0, 0.0, 0.0]), h(H3), _power_law)
    if name == "hill_crest":
        return Setting(name, np.array([0.0, 0.0, 40.0]), h(H3), _hill)
    if name == "hill_flank":
        # 150 m east of the crest: terrain 40 / (1 + 0.75^2) = 25.6 m
        return Setting(name, np.array([150.0, 0.0, 40.0 / (1.0 + 0.75**2)]), h(H3), _hill)
    if name == "hemisphere":
        return Setting(name, np.array([4.0, 3.0, 20.1]), h([10.0, 30.0, 60.0]), _hemisphere)
    if name == "openfoam":
        hh = h(H3)
        return Setting(name, OPENFOAM_LIDAR, hh, None, _openfoam_field(tuple(hh.tolist())),
                       OPENFOAM_INFLOW)
    raise ValueError(f"unknown setting {name!r}; one of {SETTINGS}")


SETTINGS = ("power_law", "hill_crest", "hill_flank", "hemisphere", "openfoam")


# ------------------------------------------------------------------------------------------
# tables and campaigns


def table(s: Setting, n_directions: int = 36, **kwargs) -> lj.ResponseTable:
    """The site's table from `simulate` at the nominal installation (level, unturned), one
    run per direction every ``360 / n_directions`` degrees, with beam vectors and the
    velocity at the beam points (`ResponseTable.from_simulations` with mounts and fields).
    `kwargs` go to `from_simulations`."""
    dirs = np.arange(n_directions) * (360.0 / n_directions)
    flows = [_flow(s, 1.0, d) for d in dirs]
    mounts = [lj.Mount(s.location, beta=float(b)) for _, b, _, _ in flows]
    sims = _table_program(s)(jnp.asarray(dirs))
    return lj.ResponseTable.from_simulations(sims, mount=mounts, fields=[f for f, *_ in flows],
                                             scan=SCAN, **kwargs)


def runs(s: Setting, n_directions: int = 36) -> lj.TableRuns:
    """The site's runs behind `table` (`lidarjax.TableRuns`: the same directions, fields,
    nominal mounts and free streams), for `lidarjax.calibrate`'s iteration on the exact
    geometry; ``runs(s).table()`` is `table(s)`."""
    dirs = np.arange(n_directions) * (360.0 / n_directions)
    flows = [_flow(s, 1.0, d) for d in dirs]
    return lj.TableRuns([f for f, *_ in flows],
                        [lj.Mount(s.location, beta=float(b)) for _, b, _, _ in flows],
                        np.stack([np.asarray(u, np.float64) for *_, u, _ in flows]), SCAN,
                        s.heights)


@cache
def _table_program(s: Setting):
    """The table's runs ``(s,)`` at unit free-stream speed, one compiled program."""

    def run(direction):
        field, beta, u, _ = _flow(s, 1.0, direction)
        return lj.simulate(field, SCAN, lj.Mount(s.location, beta=beta), s.heights, u_ref=u)

    return jax.jit(jax.vmap(run))


def campaigns(s: Setting, rng: np.random.Generator, n_campaigns: int, n_records: int, *,
              max_tilt: float = MAX_TILT, max_north: float = MAX_NORTH, sigma: float = 0.1,
              speed=(4.0, 14.0), offsets=None) -> dict:
    """`n_campaigns` campaigns of `n_records` records each: per campaign a true north offset
    uniform in ``+-max_north`` and pitch, roll uniform in ``+-max_tilt`` degrees (or the
    given `offsets` ``(c, 3)``: north offset, pitch, roll); per record a free stream uniform
    in `speed` m/s and [0, 360) degrees; Gaussian LOS noise `sigma` m/s.

    **Returns:** a dict of ``los (c, n, h, b)``, ``offsets (c, 3)`` (calibrate's
    ``(epsilon, pitch, roll)``, see the module docstring), ``ref_speed``, ``ref_direction``
    ``(c, n, h)``."""
    c, n, h = n_campaigns, n_records, s.heights.size
    if offsets is None:
        offsets = np.stack([rng.uniform(-max_north, max_north, c),
                            rng.uniform(-max_tilt, max_tilt, c),
                            rng.uniform(-max_tilt, max_tilt, c)], -1)
    offsets = np.asarray(offsets, np.float64).reshape(c, 3)
    u = rng.uniform(*speed, (c, n))
    d = rng.uniform(0.0, 360.0, (c, n))
    los = simulate_los(s, u, d, -offsets[:, 0], offsets[:, 1], offsets[:, 2])
    los = los + sigma * rng.standard_normal(los.shape)
    return {"los": los, "offsets": offsets,
            "ref_speed": np.broadcast_to(u[..., None], (c, n, h)),
            "ref_direction": np.broadcast_to(d[..., None], (c, n, h))}


def estimate(table, camp: dict, *, reference: bool, calibrate=None, runs=None) -> dict:
    """`lidarjax.calibrate` (or the given `calibrate`) on every campaign, with or without the
    reference (and with the table's `runs`, iterating on the exact geometry, when given):
    ``z = (estimate - truth) / std`` ``(c, k)`` for the identifiable offsets (epsilon only
    with a reference), the estimates, standard errors and truths, and whether each
    converged."""
    cal = lj.calibrate if calibrate is None else calibrate
    if runs is not None:
        cal = functools.partial(cal, runs=runs)
    sel = [0, 1, 2] if reference else [1, 2]
    est, std, conv, rebuilds = [], [], [], []
    for i in range(camp["los"].shape[0]):
        ref = (camp["ref_speed"][i], camp["ref_direction"][i]) if reference else None
        res = cal(camp["los"][i], table, reference=ref)
        est.append(np.asarray(res.offset)[sel])
        std.append(np.asarray(res.std)[sel])
        conv.append(bool(res.converged))
        rebuilds.append(int(getattr(res, "rebuilds", 0)))
    est, std = np.array(est), np.array(std)
    truth = camp["offsets"][:, sel]
    names = ("epsilon", "pitch", "roll")
    return {"names": [names[j] for j in sel], "estimate": est, "std": std, "truth": truth,
            "z": (est - truth) / std, "converged": np.array(conv),
            "rebuilds": np.array(rebuilds)}


def summary(z: np.ndarray, truth: np.ndarray) -> dict:
    """Per offset: coverage of the 95 % intervals, mean and sd of z, and the mean of
    ``z * sign(truth)`` (a bias proportional to the offset, which cancels in the plain mean
    when the offsets are drawn symmetric about zero)."""
    z = np.asarray(z)
    return {"coverage": np.mean(np.abs(z) < 1.959964, 0).tolist(),
            "mean_z": np.mean(z, 0).tolist(), "sd_z": np.std(z, 0, ddof=1).tolist(),
            "mean_z_signed": np.mean(z * np.sign(truth), 0).tolist(),
            "n": int(z.shape[0])}
