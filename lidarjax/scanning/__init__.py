"""Scanning lidars (Halo StreamLine, Windcube 200S/400S, the DTU SpinnerLidar): rays and
range gates with the instrument's timing, their forward model in steady fields and through
time, and the reconstructions they feed (VAD/DBS profiles, dual-Doppler vectors).

- `pattern`: `ScanPattern`, one repetition of a scan (rays, timing, gates).
- `presets`: `ppi`, `rhi`, `stare`, `vad`, `spinner_rosette`, `instrument_probe`.
- `simulate`: `simulate_scan` (steady), `simulate_scan_series` (through time), `ScanResult`;
  `gate_nodes` (the range-weighting quadrature of every gate) and `scan_points` (every point
  sampled, for a mesh's exact interpolation) are `lidarjax.beam`'s, re-exported here.
- `profiles`: `vad_fit`, the per-gate least-squares sine fit at any elevation.
- `dual`: `dual_doppler`, vectors where two lidars' beams cross.

See ``docs/scanning.md``.
"""

from ..beam import gate_nodes as gate_nodes
from ..beam import scan_points as scan_points
from .dual import DUAL_ILL_CONDITIONED as DUAL_ILL_CONDITIONED
from .dual import CrossingGeometry as CrossingGeometry
from .dual import DualDoppler as DualDoppler
from .dual import crossing_geometry as crossing_geometry
from .dual import dual_doppler as dual_doppler
from .dual import simulate_dual_doppler as simulate_dual_doppler
from .pattern import ScanPattern as ScanPattern
from .pattern import gate_ranges as gate_ranges
from .pattern import ray_unit_vectors as ray_unit_vectors
from .pattern import suggest_sub_rays as suggest_sub_rays
from .presets import INSTRUMENTS as INSTRUMENTS
from .presets import instrument_probe as instrument_probe
from .presets import ppi as ppi
from .presets import rhi as rhi
from .presets import rosette_angles as rosette_angles
from .presets import spinner_rosette as spinner_rosette
from .presets import stare as stare
from .presets import vad as vad
from .profiles import VadProfile as VadProfile
from .profiles import vad_fit as vad_fit
from .simulate import ScanResult as ScanResult
from .simulate import simulate_scan as simulate_scan
from .simulate import simulate_scan_series as simulate_scan_series

__all__ = [
    "gate_nodes", "scan_points", "DUAL_ILL_CONDITIONED", "CrossingGeometry", "DualDoppler",
    "crossing_geometry", "dual_doppler", "simulate_dual_doppler", "ScanPattern", "gate_ranges",
    "ray_unit_vectors", "suggest_sub_rays", "INSTRUMENTS", "instrument_probe", "ppi", "rhi",
    "rosette_angles", "spinner_rosette", "stare", "vad", "VadProfile", "vad_fit", "ScanResult",
    "simulate_scan", "simulate_scan_series",
]
