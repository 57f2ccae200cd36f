"""File readers and writers for lidarjax (plain numpy, no jit).

- `settings`: the seed UDF's `settings.dat` (`read_settings`, `write_settings`, `Settings`).
- `seed_output`: the seed's output table, its azimuth convention, CSV and NetCDF writers.
- `sta`, `rtd`: Windcube 10-minute statistics and line-of-sight records.
- `zephir`: ZephIR 10-minute CSV exports.
- `record_set`: `RecordSet`, the common record type every reader's result converts to
  (`to_record_set()`), as `lidarjax.load_records` returns it.
- `monitor_points`: the lidar's sample points as CFD monitor points (`MonitorPoints`) and their
  files (OpenFOAM ``probes`` dictionary and output, zCFD, CSV).
- `fields`: CFD velocity fields (`.npz`, NetCDF, Fluent ASCII, OpenFOAM cases) for
  `lidarjax.GridField`.
- `openfoam`: OpenFOAM case directories (mesh + `U`, ASCII/binary/gzip) and OpenFOAM's own
  cellPoint interpolation at arbitrary points (`sample_openfoam`).
- `snapshots`: unsteady CFD runs (OpenFOAM time directories, NetCDF with a time axis, one
  file per snapshot) as one time-dependent field (`load_field_sequence`).
- `vtk`: VTK unstructured meshes (`.vtu`, `.vtk`, `.vtm`; extra ``meshio``).
- `hpl`, `windcube_scan`, `scan_netcdf`: scanning lidars (Halo `.hpl`, Windcube 200S/400S
  NetCDF; CF NetCDF of scans, time x beam x range).
- `layout`: wind-farm layouts (seed 004's `<name> <easting> <northing>`), turbine types.
- `turbulence`: turbulence boxes (HAWC2 binary, TurbSim `.bts`).
- `motion`: platform motion logs.
- `tables`: response tables (`save_table`, `load_table`).

The io layer sits above the core and the scenes: readers build core objects (a `GridField`,
a `ResponseTable`, a `TurbulenceBox`), the core never imports io. Record flags are
`lidarjax.RecordFlag`.

Optional extras: `pandas` (`Record.to_pandas`), `netcdf` (xarray; NetCDF read/write),
`progress` (tqdm progress bars). Each raises an `ImportError` naming the extra when used
without it.
"""

from .._deprecated import deprecated_getattr as _deprecated_getattr
from ._exact import CellPointField as CellPointField
from ._exact import CellPointSnapshots as CellPointSnapshots
from ._exact import CellPointTets as CellPointTets
from ._exact import cellpoint_field as cellpoint_field
from ._exact import simulate_points as simulate_points
from .fields import FieldArrays as FieldArrays
from .fields import FieldLoadReport as FieldLoadReport
from .fields import load_field as load_field
from .fields import read_field_arrays as read_field_arrays
from .fields import read_fluent_points as read_fluent_points
from .fields import resample_to_grid as resample_to_grid
from .fields import save_field_netcdf as save_field_netcdf
from .fields import save_field_npz as save_field_npz
from .hpl import HaloScan as HaloScan
from .hpl import read_hpl as read_hpl
from .layout import FarmLayout as FarmLayout
from .layout import read_farm as read_farm
from .layout import read_layout as read_layout
from .layout import read_turbine_type as read_turbine_type
from .monitor_points import MonitorPoints as MonitorPoints
from .monitor_points import OpenFoamProbes as OpenFoamProbes
from .monitor_points import read_monitor_points_csv as read_monitor_points_csv
from .monitor_points import read_monitor_values_csv as read_monitor_values_csv
from .monitor_points import read_openfoam_probes as read_openfoam_probes
from .monitor_points import write_monitor_points_csv as write_monitor_points_csv
from .monitor_points import write_openfoam_probes as write_openfoam_probes
from .monitor_points import write_zcfd_probes as write_zcfd_probes
from .motion import read_motion_csv as read_motion_csv
from .openfoam import OpenFOAMField as OpenFOAMField
from .openfoam import is_openfoam_case as is_openfoam_case
from .openfoam import openfoam_times as openfoam_times
from .openfoam import read_openfoam_field as read_openfoam_field
from .openfoam import read_openfoam_mesh as read_openfoam_mesh
from .openfoam import resample_openfoam as resample_openfoam
from .openfoam import sample_openfoam as sample_openfoam
from .record_set import RecordSet as RecordSet
from .rtd import BEAM_AZIMUTHS as BEAM_AZIMUTHS
from .rtd import InstrumentReconstruction as InstrumentReconstruction
from .rtd import RtdBeams as RtdBeams
from .rtd import RtdRecord as RtdRecord
from .rtd import group_rtd as group_rtd
from .rtd import instrument_reconstruction as instrument_reconstruction
from .rtd import read_rtd as read_rtd
from .scan_netcdf import read_scan_netcdf as read_scan_netcdf
from .scan_netcdf import write_scan_netcdf as write_scan_netcdf
from .seed_output import SEED_COLUMNS as SEED_COLUMNS
from .seed_output import SEED_UNITS as SEED_UNITS
from .seed_output import CsvTable as CsvTable
from .seed_output import meteorological_from_seed as meteorological_from_seed
from .seed_output import read_seed_output as read_seed_output
from .seed_output import read_table_csv as read_table_csv
from .seed_output import seed_from_meteorological as seed_from_meteorological
from .seed_output import seed_output_filename as seed_output_filename
from .seed_output import write_netcdf as write_netcdf
from .seed_output import write_seed_output as write_seed_output
from .seed_output import write_table_csv as write_table_csv
from .settings import Settings as Settings
from .settings import read_settings as read_settings
from .settings import write_settings as write_settings
from .snapshots import load_field_sequence as load_field_sequence
from .sta import STA_FIELDS as STA_FIELDS
from .sta import StaRecord as StaRecord
from .sta import read_sta as read_sta
from .sta import write_series_sta as write_series_sta
from .sta import write_sta as write_sta
from .tables import load_table as load_table
from .tables import save_table as save_table
from .turbulence import TurbSimField as TurbSimField
from .turbulence import read_hawc2_box as read_hawc2_box
from .turbulence import read_turbsim as read_turbsim
from .turbulence import write_hawc2_box as write_hawc2_box
from .turbulence import write_turbsim as write_turbsim
from .windcube_scan import WindcubeScan as WindcubeScan
from .windcube_scan import read_windcube_scan as read_windcube_scan
from .zephir import ZephirRecord as ZephirRecord
from .zephir import read_zephir_csv as read_zephir_csv

__all__ = [
    "CellPointField", "CellPointSnapshots", "CellPointTets", "cellpoint_field", "simulate_points",
    "FieldArrays", "FieldLoadReport", "load_field", "read_field_arrays", "read_fluent_points",
    "resample_to_grid", "save_field_netcdf", "save_field_npz", "HaloScan", "read_hpl", "FarmLayout",
    "read_farm", "read_layout", "read_turbine_type", "MonitorPoints", "OpenFoamProbes",
    "read_monitor_points_csv", "read_monitor_values_csv", "read_openfoam_probes",
    "write_monitor_points_csv", "write_openfoam_probes", "write_zcfd_probes", "read_motion_csv",
    "OpenFOAMField", "is_openfoam_case", "openfoam_times", "read_openfoam_field",
    "read_openfoam_mesh", "resample_openfoam", "sample_openfoam", "RecordSet", "BEAM_AZIMUTHS",
    "InstrumentReconstruction", "RtdBeams", "RtdRecord", "group_rtd", "instrument_reconstruction",
    "read_rtd", "read_scan_netcdf", "write_scan_netcdf", "SEED_COLUMNS", "SEED_UNITS", "CsvTable",
    "meteorological_from_seed", "read_seed_output", "read_table_csv", "seed_from_meteorological",
    "seed_output_filename", "write_netcdf", "write_seed_output", "write_table_csv", "Settings",
    "read_settings", "write_settings", "load_field_sequence", "STA_FIELDS", "StaRecord", "read_sta",
    "write_series_sta", "write_sta", "load_table", "save_table", "TurbSimField", "read_hawc2_box",
    "read_turbsim", "write_hawc2_box", "write_turbsim", "WindcubeScan", "read_windcube_scan",
    "ZephirRecord", "read_zephir_csv",
]

__getattr__ = _deprecated_getattr(__name__)
