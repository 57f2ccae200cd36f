"""Scenes: flows defined by formulas rather than files, usable wherever a `GridField` is.

- `lidarjax.scenes.analytic`: the validation flows (uniform, power law, linear, hemisphere,
  hill), all linear in the free stream.
- `lidarjax.scenes.turbulence`: `FrozenTurbulence`, any mean field plus a
  `lidarjax.TurbulenceBox` advected with the wind (Taylor), time-dependent through
  ``sample_local_at`` (boxes and their generators: `lidarjax.turbulence`).
- `lidarjax.scenes.farm`: wind-farm wakes (`WindFarm`: top-hat Jensen or Gaussian wakes,
  yaw deflection, turbine interaction), non-linear in direction.

Every scene is an `AbstractField` (CFD frame: ``+x`` east, ``+y`` north, ``+z`` up, metres
and m/s; directions meteorological), dynamic and differentiable in all its parameters.
"""

from .._deprecated import deprecated_getattr as _deprecated_getattr
from .analytic import Hemisphere as Hemisphere
from .analytic import Hill as Hill
from .analytic import Linear as Linear
from .analytic import PowerLaw as PowerLaw
from .analytic import Uniform as Uniform
from .analytic import hemisphere as hemisphere
from .analytic import hill as hill
from .analytic import linear as linear
from .analytic import power_law as power_law
from .analytic import uniform as uniform
from .farm import FarmState as FarmState
from .farm import WindFarm as WindFarm
from .farm import nacelle_mount as nacelle_mount
from .farm import overlap_area as overlap_area
from .farm import wind_farm as wind_farm
from .turbulence import FrozenTurbulence as FrozenTurbulence
from .turbulence import frozen_turbulence as frozen_turbulence

__all__ = [
    "Hemisphere", "Hill", "Linear", "PowerLaw", "Uniform", "hemisphere", "hill", "linear",
    "power_law", "uniform", "FarmState", "WindFarm", "nacelle_mount", "overlap_area", "wind_farm",
    "FrozenTurbulence", "frozen_turbulence",
]

__getattr__ = _deprecated_getattr(__name__)
