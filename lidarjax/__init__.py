"""lidarjax: differentiable wind-lidar simulation in CFD fields and free-stream correction."""

import importlib.metadata

from . import io as io
from . import scenes as scenes
from .angles import direction_difference as direction_difference
from .angles import horizontal_speed as horizontal_speed
from .angles import seed_azimuth as seed_azimuth
from .angles import wind_direction as wind_direction
from .angles import wrap180 as wrap180
from .corrections import correction_factors as correction_factors
from .field import AbstractField as AbstractField
from .field import GridField as GridField
from .flags import Flag as Flag
from .forward import Simulation as Simulation
from .forward import simulate as simulate
from .mount import Mount as Mount
from .probe import AbstractProbe as AbstractProbe
from .probe import PointProbe as PointProbe
from .scan import Scan as Scan
from .scan import reconstruct as reconstruct
from .scan import windcube_v1 as windcube_v1
from .scan import windcube_v2 as windcube_v2
from .scan import zephir as zephir

try:
    __version__ = importlib.metadata.version("lidarjax")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"
