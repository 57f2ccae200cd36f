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

from ._common import BLOCKING_FLAGS as BLOCKING_FLAGS
from ._common import MIN_AVAILABILITY as MIN_AVAILABILITY
from ._common import RecordFlag as RecordFlag
from .fields import FieldArrays as FieldArrays
from .fields import FieldLoadReport as FieldLoadReport
from .fields import load_field as load_field
from .fields import read_field_arrays as read_field_arrays
from .fields import read_fluent_points as read_fluent_points
from .fields import resample_to_grid as resample_to_grid
from .fields import save_field_netcdf as save_field_netcdf
from .fields import save_field_npz as save_field_npz
from .rtd import BEAM_AZIMUTHS as BEAM_AZIMUTHS
from .rtd import InstrumentReconstruction as InstrumentReconstruction
from .rtd import RtdBeams as RtdBeams
from .rtd import RtdRecord as RtdRecord
from .rtd import group_rtd as group_rtd
from .rtd import instrument_reconstruction as instrument_reconstruction
from .rtd import read_rtd as read_rtd
from .seed_output import SEED_COLUMNS as SEED_COLUMNS
from .seed_output import SEED_UNITS as SEED_UNITS
from .seed_output import CsvTable as CsvTable
from .seed_output import meteorological_from_seed as meteorological_from_seed
from .seed_output import read_seed_output as read_seed_output
from .seed_output import read_table_csv as read_table_csv
from .seed_output import seed_azimuth as seed_azimuth
from .seed_output import seed_from_meteorological as seed_from_meteorological
from .seed_output import seed_output_filename as seed_output_filename
from .seed_output import write_netcdf as write_netcdf
from .seed_output import write_seed_output as write_seed_output
from .seed_output import write_table_csv as write_table_csv
from .settings import Settings as Settings
from .settings import read_settings as read_settings
from .settings import write_settings as write_settings
from .sta import STA_FIELDS as STA_FIELDS
from .sta import StaRecord as StaRecord
from .sta import read_sta as read_sta
from .sta import write_sta as write_sta
from .tables import load_table as load_table
from .tables import save_table as save_table
from .zephir import ZephirRecord as ZephirRecord
from .zephir import read_zephir_csv as read_zephir_csv
