"""Design by gradients: where to put a lidar and which scan to run, found by optimisation
through the differentiable forward model.

- `placement`: `design_placement` for profiling lidars (location in a `RegionBox` or
  `RegionPolygon`, optionally cone angle and heading; objective over all inflow directions
  weighted by a wind rose).
- `scanning`: `design_dual_doppler` (two scanning lidars' positions for the smallest
  dual-Doppler retrieval variance) and `design_vad` (elevation and ray count of a PPI/VAD for
  the smallest VAD-fit variance).
- `control`: `design_lac_scan` (focus distance, half-cone angle, beam count and range gate of
  a nacelle lidar for the widest lidar–rotor coherence bandwidth, lidar-assisted control).

See ``docs/design.md``.
"""

from .control import TURBINES as TURBINES
from .control import LacDesign as LacDesign
from .control import Turbine as Turbine
from .control import design_lac_scan as design_lac_scan
from .control import lac_objective as lac_objective
from .placement import OBJECTIVES as OBJECTIVES
from .placement import Placement as Placement
from .placement import RegionBox as RegionBox
from .placement import RegionPolygon as RegionPolygon
from .placement import design_placement as design_placement
from .placement import evaluate_placements as evaluate_placements
from .placement import placement_objective as placement_objective
from .placement import placement_problem as placement_problem
from .scanning import DualDopplerDesign as DualDopplerDesign
from .scanning import RegionRing as RegionRing
from .scanning import VadDesign as VadDesign
from .scanning import design_dual_doppler as design_dual_doppler
from .scanning import design_vad as design_vad
from .scanning import dual_doppler_variance as dual_doppler_variance
from .scanning import vad_variance as vad_variance

__all__ = [
    "TURBINES", "LacDesign", "Turbine", "design_lac_scan", "lac_objective",
    "OBJECTIVES", "Placement", "RegionBox", "RegionPolygon", "design_placement",
    "evaluate_placements", "placement_objective", "placement_problem", "DualDopplerDesign",
    "RegionRing", "VadDesign", "design_dual_doppler", "design_vad", "dual_doppler_variance",
    "vad_variance",
]
