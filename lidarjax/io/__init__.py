"""File readers and writers for lidarjax (plain numpy, no jit).

- `settings`: the seed UDF's `settings.dat` (`read_settings`, `write_settings`, `Settings`).
- `seed_output`: the seed's output table, its azimuth convention, CSV and NetCDF writers.
- `sta`, `rtd`: Windcube 10-minute statistics and line-of-sight records.
- `zephir`: ZephIR 10-minute CSV exports.
- `fields`: CFD velocity fields (`.npz`, NetCDF, Fluent ASCII) for `lidarjax.GridField`.

Optional extras: `pandas` (`Record.to_pandas`), `netcdf` (xarray; NetCDF read/write),
`progress` (tqdm progress bars). Each raises an `ImportError` naming the extra when used
without it.
"""

from .settings import Settings as Settings
from .settings import read_settings as read_settings
from .settings import write_settings as write_settings
