"""Design by gradients of a lidar scan for lidar-assisted control: which focus distance,
half-cone angle, number of beams or scan points and range gate give the lidar estimate of
the rotor-effective wind speed that is coherent with the rotor's to the highest frequency
(or has the smallest error after the optimal filter), under the analytic spectra of
`lidarjax.control`.

- `TURBINES`: presets (rotor radius, hub height, rated wind speed; metres and m/s).
- `design_lac_scan`: the optimum over a box of the continuous variables (the shared search:
  a coarse grid, then BFGS from the best few candidates, every objective evaluation
  counted), the discrete number of points in an outer loop.
- `lac_objective`: the objective at given variables (for grid searches and plots).

Variables (names in `LacDesign.names`): ``distance`` (the focus plane's upstream distance
from the lidar, m), ``half_cone`` (angle between each beam and the rotor axis, degrees),
``gate_length`` (pulsed lidars' range gate, m). A variable given as a number is held fixed, a
``(lo, hi)`` pair is optimised.
"""

from __future__ import annotations

from collections.abc import Sequence

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..control import KaimalInflow, MannInflow, cone_points, lac_spectra, lidar_samples, rotor_disc
from ..control.spectra import _inflow_spectra, coherence_bandwidth
from ..probe import CWProbe, PulsedProbe
from . import _search

__all__ = ["LAC_OBJECTIVES", "TURBINES", "LacDesign", "Turbine", "design_lac_scan", "lac_objective"]

#: ``"bandwidth"``: maximise the coherence bandwidth (the value is minus it, Hz);
#: ``"error"``: minimise ``sum_f S_RR (1 - gamma^2) df``, the variance (m^2/s^2) of the REWS
#: error left by the optimal linear filter of the lidar estimate over the frequency grid.
LAC_OBJECTIVES = ("bandwidth", "error")
VARIABLES = ("distance", "half_cone", "gate_length")


class Turbine(eqx.Module):
    """A turbine preset: rotor `radius` (m), `hub_height` (m), `rated_speed` (m/s)."""

    radius: float
    hub_height: float
    rated_speed: float


#: The NREL 5 MW (Jonkman et al. 2009) and IEA 15 MW (Gaertner et al. 2020) reference turbines.
TURBINES = {"NREL5MW": Turbine(63.0, 90.0, 11.4), "IEA15MW": Turbine(120.0, 150.0, 10.59)}


class _Problem(eqx.Module):
    rotor: object
    inflow: KaimalInflow | MannInflow
    frequency: jax.Array
    probe: object
    fixed: jax.Array  # (3,) values of the fixed variables (distance, half_cone, gate_length)
    free: tuple = eqx.field(static=True)  # indices of the optimised variables
    n_points: int = eqx.field(static=True)
    objective: str = eqx.field(static=True)


def _evaluate(pb: _Problem, x):
    v = pb.fixed
    for i, k in enumerate(pb.free):
        v = v.at[k].set(x[i])
    probe = pb.probe
    if isinstance(probe, PulsedProbe):
        probe = eqx.tree_at(lambda p: p.gate_length, probe, v[2])
    focus = cone_points(v[0], v[1], pb.n_points, azimuth_offset=45.0 if pb.n_points == 4 else 0.0)
    samples = lidar_samples(focus, probe=probe)
    sp = lac_spectra(samples, pb.rotor, pb.inflow, pb.frequency)
    bandwidth = _exact_bandwidth(pb, samples, coherence_bandwidth(sp)[0])
    if pb.objective == "bandwidth":
        return -bandwidth, bandwidth
    return jnp.sum(sp.S_RR * (1 - sp.coherence) * jnp.gradient(pb.frequency)), bandwidth


def _exact_bandwidth(pb, samples, f_grid):
    """The bandwidth as the root of ``gamma^2(f) = 0.5`` of the analytic spectra (two Newton
    steps from the grid's crossing), differentiable by the implicit-function theorem: the
    grid's linear interpolation has a gradient that jumps between grid cells."""

    def excess(f):
        return _inflow_spectra(samples, pb.rotor, pb.inflow, jnp.reshape(f, (1,))).coherence[0] - 0.5

    def newton(f):
        g, dg = jax.jvp(excess, (f,), (jnp.ones_like(f),))
        return f - g / jax.lax.stop_gradient(dg)

    # two steps in one loop body (one copy of the spectra's graph to compile, not two)
    f = jax.lax.stop_gradient(jax.lax.fori_loop(0, 2, lambda _, f: newton(f), jax.lax.stop_gradient(f_grid)))
    return newton(f)


def _objective(pb, x):
    value, bandwidth = _evaluate(pb, x)
    value, ok = _search.masked(value, jnp.isfinite(value))
    return value, ok, bandwidth


class LacDesign(eqx.Module):
    """Result of `design_lac_scan`.

    **Fields:** `names` (the optimised variables), `x` (their best values: m, degrees, m),
    `n_points` (the best count), `value` (the objective: minus the bandwidth in Hz, or the
    error variance in m^2/s^2), `bandwidth` (Hz, the root of ``gamma^2 = 0.5`` of the analytic
    spectra), `scan_radius` (``distance tan(half_cone)``,
    m), `counts`, `values` and `xs` per count tried, `n_evaluations` (objective evaluations,
    every count together), `converged`.
    """

    names: tuple
    x: np.ndarray
    n_points: int
    value: float
    bandwidth: float
    scan_radius: float
    counts: np.ndarray
    values: np.ndarray
    xs: np.ndarray
    n_evaluations: int
    converged: bool


def _problem(turbine, inflow, *, n_points, distance, half_cone, gate_length, lidar, frequency, spacing,
             objective):
    if objective not in LAC_OBJECTIVES:
        raise ValueError(f"design_lac_scan: objective={objective!r} is not one of {LAC_OBJECTIVES}")
    if isinstance(turbine, str):
        if turbine not in TURBINES:
            raise ValueError(f"design_lac_scan: turbine={turbine!r} is not one of {sorted(TURBINES)} "
                             "(or give a Turbine)")
        turbine = TURBINES[turbine]
    if not isinstance(inflow, KaimalInflow | MannInflow):
        raise ValueError(f"design_lac_scan: inflow must be a KaimalInflow or a MannInflow, got "
                         f"{type(inflow).__name__}")
    if lidar not in ("pulsed", "cw"):
        raise ValueError(f"design_lac_scan: lidar={lidar!r} must be 'pulsed' or 'cw'")
    spec = {"distance": distance, "half_cone": half_cone, "gate_length": gate_length}
    if lidar == "cw":
        spec["gate_length"] = 1.0  # a CW lidar has no gate
    fixed, free, lo, hi = [], [], [], []
    for i, name in enumerate(VARIABLES):
        value = spec[name]
        if np.ndim(value) == 0:
            fixed.append(float(value))
        else:
            a, b = (float(t) for t in value)
            if not (np.isfinite(a) and np.isfinite(b) and 0 < a < b):
                raise ValueError(f"design_lac_scan: {name}={value!r} must be a number or an increasing "
                                 "positive (lo, hi) pair")
            fixed.append(a)
            free.append(i)
            lo.append(a)
            hi.append(b)
    if not free:
        raise ValueError("design_lac_scan: nothing to optimise: give at least one variable as a (lo, hi) pair")
    if frequency is None:
        frequency = np.linspace(0.002, 0.4, 100)
    probe = PulsedProbe(30.0, spec["gate_length"] if np.ndim(spec["gate_length"]) == 0 else lo[-1], n_nodes=7) \
        if lidar == "pulsed" else CWProbe(n_nodes=9)
    rotor = rotor_disc(turbine.radius, spacing=turbine.radius / spacing)
    pb = _Problem(rotor, inflow, jnp.asarray(frequency), probe, jnp.asarray(fixed), tuple(free),
                  int(n_points), objective)
    names = tuple(VARIABLES[i] for i in free)
    return pb, names, jnp.asarray(lo), jnp.asarray(hi)


def lac_objective(turbine, inflow: KaimalInflow | MannInflow, x, *, n_points: int = 4, distance=(50.0, 300.0),
                  half_cone=(5.0, 40.0), gate_length=30.0, lidar: str = "pulsed", frequency=None,
                  spacing: float = 10.0, objective: str = "bandwidth"):
    """The objective of `design_lac_scan` (same arguments) at variables `x` ``(m, d)`` (the
    free variables in the order distance, half_cone, gate_length): ``(values (m,), bandwidths
    (m,))``, one compiled evaluation per point."""
    pb, _, _, _ = _problem(turbine, inflow, n_points=n_points, distance=distance, half_cone=half_cone,
                           gate_length=gate_length, lidar=lidar, frequency=frequency, spacing=spacing,
                           objective=objective)
    values, bw = _objective_map(pb, jnp.asarray(x, pb.fixed.dtype))
    return np.asarray(values), np.asarray(bw)


@jax.jit
def _objective_map(pb, x):
    """``(values, bandwidths)`` at every row of `x`: one program per problem structure (a
    `jax.jit` of a fresh lambda per call would compile again every call)."""
    return jax.lax.map(lambda xi: _objective(pb, xi)[::2], x)


def design_lac_scan(turbine, inflow: KaimalInflow | MannInflow, *, n_points: Sequence[int] = (4,),
                    distance=(50.0, 300.0), half_cone=(5.0, 40.0), gate_length=30.0, lidar: str = "pulsed",
                    frequency=None, spacing: float = 10.0, objective: str = "bandwidth",
                    n_coarse: int = 9, n_starts: int = 2, max_steps: int = 15) -> LacDesign:
    """The scan of a nacelle (or spinner) lidar on the hub that is best for feed-forward
    control, by gradients (see the module docs).

    **Arguments:**

    - `turbine`: a `TURBINES` key (``"NREL5MW"``, ``"IEA15MW"``) or a `Turbine`.
    - `inflow`: the turbulence: `lidarjax.control.KaimalInflow` (mean wind, intensity,
      scale) or `lidarjax.control.MannInflow` (mean wind, level, length scale, shear
      anisotropy; one code path: the spectra dispatch on its type).
    - `n_points`: beam or scan-point counts to try (outer loop), on a cone evenly in azimuth.
    - `distance` (m), `half_cone` (degrees), `gate_length` (m, pulsed only): a number (fixed)
      or a ``(lo, hi)`` box to optimise in.
    - `lidar`: ``"pulsed"`` (`lidarjax.PulsedProbe`, 30 m pulse) or ``"cw"``
      (`lidarjax.CWProbe`, default optics).
    - `frequency`: the spectra's grid (Hz); default 100 points over 0.002-0.4 Hz.
    - `spacing`: rotor grid points per radius (10: a 10 x 10-per-quadrant disc).
    - `objective`: one of `LAC_OBJECTIVES`.
    - `n_coarse`, `n_starts`, `max_steps`: the search (coarse grid size, BFGS starts and steps).

    **Returns:** `LacDesign`.
    """
    results, xs = [], []
    for n in n_points:
        if not isinstance(n, int | np.integer) or n < 1:
            raise ValueError(f"design_lac_scan: n_points must be positive integers, got {n!r}")
        pb, names, lo, hi = _problem(turbine, inflow, n_points=int(n), distance=distance,
                                     half_cone=half_cone, gate_length=gate_length, lidar=lidar,
                                     frequency=frequency, spacing=spacing, objective=objective)
        r = _search.search(_objective, pb, lo, hi, n_coarse=n_coarse, n_starts=n_starts,
                           solver=_search.default_solver(lo.dtype), max_steps=max_steps, batch_size=16)
        results.append((r, pb))
        xs.append(r["x"] if r["feasible"] else np.full(len(names), np.nan))
    values = np.array([r["value"] if r["feasible"] else np.nan for r, _ in results])
    if not np.any(np.isfinite(values)):
        raise ValueError("design_lac_scan: no feasible scan (the coherence never reaches 0.5 on the grid, "
                         "or never falls below it): widen the frequency grid")
    b = int(np.nanargmin(values))
    r, pb = results[b]
    full = np.asarray(pb.fixed).copy()
    full[list(pb.free)] = r["x"]
    return LacDesign(names=names, x=np.asarray(r["x"]), n_points=int(n_points[b]), value=float(values[b]),
                     bandwidth=float(r["aux"]), scan_radius=float(full[0] * np.tan(np.deg2rad(full[1]))),
                     counts=np.asarray(n_points), values=values, xs=np.asarray(xs),
                     n_evaluations=sum(int(q["n_evaluations"]) for q, _ in results),
                     converged=bool(r["converged"]))
