"""lidarjax: differentiable wind-lidar simulation in CFD fields and free-stream correction."""

import importlib.metadata

from . import io as io
from . import scenes as scenes
from . import sectors as sectors
from . import zephycube as zephycube
from .angles import direction_difference as direction_difference
from .angles import horizontal_speed as horizontal_speed
from .angles import seed_azimuth as seed_azimuth
from .angles import wind_direction as wind_direction
from .angles import wrap180 as wrap180
from .batch import simulate_sectors as simulate_sectors
from .batch import stack_fields as stack_fields
from .batch import stack_mounts as stack_mounts
from .batch import unstack_field as unstack_field
from .cfd_probes import ProbeField as ProbeField
from .cfd_probes import ProbeLocations as ProbeLocations
from .cfd_probes import probe_locations as probe_locations
from .cfd_probes import simulate_from_probes as simulate_from_probes
from .corrections import correction_factors as correction_factors
from .field import AbstractField as AbstractField
from .field import GridField as GridField
from .flags import Flag as Flag
from .footprint import scan_bounds as scan_bounds
from .forward import Simulation as Simulation
from .forward import simulate as simulate
from .inverse import InverseFlag as InverseFlag
from .inverse import Inversion as Inversion
from .inverse import invert as invert
from .inverse import invert_reconstructed as invert_reconstructed
from .motion import SampledMotion as SampledMotion
from .motion import SinusoidalMotion as SinusoidalMotion
from .mount import Mount as Mount
from .probe import AbstractProbe as AbstractProbe
from .probe import CWProbe as CWProbe
from .probe import PointProbe as PointProbe
from .probe import PulsedProbe as PulsedProbe
from .records import RecordFlag as RecordFlag
from .response import PeriodicSpline as PeriodicSpline
from .response import ResponseTable as ResponseTable
from .roses import CorrectionRose as CorrectionRose
from .roses import correction_rose as correction_rose
from .roses import sector_rose as sector_rose
from .scan import Scan as Scan
from .scan import nacelle_2beam as nacelle_2beam
from .scan import nacelle_4beam as nacelle_4beam
from .scan import nacelle_shear as nacelle_shear
from .scan import reconstruct as reconstruct
from .scan import windcube_v1 as windcube_v1
from .scan import windcube_v2 as windcube_v2
from .scan import zephir as zephir
from .sensitivity import Budget as Budget
from .sensitivity import Sensitivity as Sensitivity
from .sensitivity import sensitivity as sensitivity
from .sensitivity import uncertainty as uncertainty
from .series import Series as Series
from .series import SeriesStatistics as SeriesStatistics
from .series import simulate_series as simulate_series
from .series import simulate_statistics as simulate_statistics
from .series import statistics as statistics
from .series import write_series_sta as write_series_sta
from .timing import Schedule as Schedule
from .timing import schedule_for as schedule_for

try:
    __version__ = importlib.metadata.version("lidarjax")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"
from . import spectral as spectral
