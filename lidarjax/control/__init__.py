"""Lidar-assisted control: the rotor-effective wind speed, its lidar estimate, their analytic
spectra and coherence, and the feed-forward filter they design (Task 52's model).

- `inflow`: `KaimalInflow` (IEC Kaimal spectra and the IEC coherence),
  `iec_turbulence_intensity`.
- `mann`: `MannInflow` (the Mann spectral tensor of lidarjax's turbulence boxes; `lac_spectra`
  integrates it over the lateral and vertical wavenumbers).
- `geometry`: `RotorDisc`/`rotor_disc`, `LidarSamples`/`lidar_samples`, `cone_points`
  (the rotor frame: ``x`` upstream along the rotor axis, metres).
- `spectra`: `lac_spectra` -> `LacSpectra` (``S_RR``, ``S_LL``, ``S_RL``, coherence,
  ``|G_RL|``), `coherence_bandwidth`, `filter_cutoff`, `filter_delay`, `buffer_time`.
- `rews`: `rotor_rews` (the REWS of any field), `lidar_rews` (the lidar's estimate, Task 52's
  processing), `rotor_to_cfd`.
- `estimate`: `series_rews` -> `RewsSeries` (the estimate from `lidarjax.simulate_series`'
  LOS of a nacelle or spinner lidar, at the times it previews, and the rotor's REWS there).
- `synthesis`: `kaimal_rews_series` (both simulated in Kaimal/IEC turbulence, Veers' method),
  `welch_coherence`, `coherence_band` (the time-domain check of the analytic coherence).

See ``docs/lidar-assisted-control.md``.
"""

from .estimate import RewsSeries as RewsSeries
from .estimate import series_rews as series_rews
from .geometry import LidarSamples as LidarSamples
from .geometry import RotorDisc as RotorDisc
from .geometry import cone_points as cone_points
from .geometry import lidar_samples as lidar_samples
from .geometry import rotor_disc as rotor_disc
from .inflow import IEC_REFERENCE_INTENSITY as IEC_REFERENCE_INTENSITY
from .inflow import KaimalInflow as KaimalInflow
from .inflow import iec_turbulence_intensity as iec_turbulence_intensity
from .mann import MannInflow as MannInflow
from .rews import lidar_rews as lidar_rews
from .rews import rotor_rews as rotor_rews
from .rews import rotor_to_cfd as rotor_to_cfd
from .spectra import HALF_POWER as HALF_POWER
from .spectra import LacSpectra as LacSpectra
from .spectra import buffer_time as buffer_time
from .spectra import coherence_bandwidth as coherence_bandwidth
from .spectra import filter_cutoff as filter_cutoff
from .spectra import filter_delay as filter_delay
from .spectra import lac_spectra as lac_spectra
from .synthesis import coherence_band as coherence_band
from .synthesis import kaimal_rews_series as kaimal_rews_series
from .synthesis import welch_coherence as welch_coherence

__all__ = [
    "HALF_POWER", "IEC_REFERENCE_INTENSITY", "KaimalInflow", "LacSpectra", "LidarSamples", "MannInflow",
    "RewsSeries",
    "RotorDisc",
    "buffer_time", "coherence_band", "coherence_bandwidth", "cone_points", "filter_cutoff", "filter_delay",
    "iec_turbulence_intensity", "kaimal_rews_series", "lac_spectra", "lidar_rews", "lidar_samples",
    "rotor_disc", "rotor_rews", "rotor_to_cfd", "series_rews", "welch_coherence",
]
