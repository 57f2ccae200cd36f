"""lidarjax: differentiable wind-lidar simulation in CFD fields and free-stream correction.

**The public API is flat** (as optimistix's): every public function and class of the core and
of the workflows is ``lidarjax.<name>``. Three families of alternatives are namespaces:
``lidarjax.scenes`` (flows defined by formulas), ``lidarjax.io`` (file readers and writers) and
``lidarjax.plots`` (figures, optional extra ``plot``). Modules are the implementation; their
constants (``lidarjax.sensitivity.OUTPUTS``) are reached through them.

**Layers**, each importing only the ones above it in this list, at module top:

1. the core (the differentiable model): ``frames``, ``angles``, ``mount``, ``scan``, ``probe``,
   ``beam``, ``field``, ``forward``, ``batch``, ``response``, ``inverse``, ``sensitivity``, ``timing``,
   ``motion``, ``series``, ``spectral``, ``turbulence`` and the others at the package root;
1.5. ``design/``: design by gradients (where to put a lidar, which scan to run), optimised
   through the core;
2. ``scenes/``: analytic flows, wind farms, frozen turbulence;
3. ``io/``: one module per file-format family;
4. ``plots.py``: figures of the core's results (matplotlib, imported only when drawing);
5. ``workflows/``: files in, files out (seed tables, records correction, CFD monitor points,
   series reports, the farm study, the demo);
6. ``cli/``: parses arguments, calls one workflow or core function, writes and prints.

``tests/test_layers.py`` enforces it.
"""

import importlib.metadata

from . import _deprecated
from . import control as control
from . import io as io
from . import plots as plots
from . import scenes as scenes
from .angles import direction_difference as direction_difference
from .angles import heading as heading
from .angles import horizontal_speed as horizontal_speed
from .angles import seed_azimuth as seed_azimuth
from .angles import wind_direction as wind_direction
from .angles import wrap180 as wrap180
from .batch import simulate_rotations as simulate_rotations
from .batch import stack_fields as stack_fields
from .batch import stack_mounts as stack_mounts
from .batch import unstack_field as unstack_field
from .batch import unstack_mounts as unstack_mounts
from .beam import ExactPoints as ExactPoints
from .beam import GradedProbe as GradedProbe
from .beam import beam_points as beam_points
from .beam import probe_for_field as probe_for_field
from .calibrate import Calibration as Calibration
from .calibrate import calibrate as calibrate
from .corrections import correction_factors as correction_factors
from .design import DualDopplerDesign as DualDopplerDesign
from .design import LacDesign as LacDesign
from .design import Placement as Placement
from .design import RegionBox as RegionBox
from .design import RegionPolygon as RegionPolygon
from .design import RegionRing as RegionRing
from .design import VadDesign as VadDesign
from .design import design_dual_doppler as design_dual_doppler
from .design import design_lac_scan as design_lac_scan
from .design import design_placement as design_placement
from .design import design_vad as design_vad
from .design import dual_doppler_variance as dual_doppler_variance
from .design import evaluate_placements as evaluate_placements
from .design import placement_objective as placement_objective
from .design import placement_problem as placement_problem
from .design import vad_variance as vad_variance
from .disturbed_sectors import DisturbedSector as DisturbedSector
from .disturbed_sectors import disturbed_sectors as disturbed_sectors
from .disturbed_sectors import excluded_width as excluded_width
from .disturbed_sectors import in_sectors as in_sectors
from .disturbed_sectors import merge_sectors as merge_sectors
from .field import AbstractField as AbstractField
from .field import FieldSequence as FieldSequence
from .field import GridField as GridField
from .field import SnapshotField as SnapshotField
from .flags import BLOCKING_FLAGS as BLOCKING_FLAGS
from .flags import MIN_AVAILABILITY as MIN_AVAILABILITY
from .flags import Flag as Flag
from .flags import InverseFlag as InverseFlag
from .flags import RecordFlag as RecordFlag
from .footprint import scan_bounds as scan_bounds
from .forward import Simulation as Simulation
from .forward import beam_gradient as beam_gradient
from .forward import simulate as simulate
from .frames import beam_directions as beam_directions
from .frames import body_to_cfd_rotation as body_to_cfd_rotation
from .frames import cfd_to_lidar_rotation as cfd_to_lidar_rotation
from .frames import cfd_to_north_rotation as cfd_to_north_rotation
from .frames import lidar_to_cfd_rotation as lidar_to_cfd_rotation
from .frames import lidar_to_north_rotation as lidar_to_north_rotation
from .frames import rotate as rotate
from .frames import rotation_x as rotation_x
from .frames import rotation_y as rotation_y
from .frames import rotation_z as rotation_z
from .frames import tilt_rotation as tilt_rotation
from .inverse import Inversion as Inversion
from .inverse import JointInversion as JointInversion
from .inverse import invert as invert
from .inverse import invert_joint as invert_joint
from .inverse import invert_joint_reconstructed as invert_joint_reconstructed
from .inverse import invert_reconstructed as invert_reconstructed
from .motion import AbstractMotion as AbstractMotion
from .motion import SampledMotion as SampledMotion
from .motion import SinusoidalMotion as SinusoidalMotion
from .mount import Mount as Mount
from .probe import AbstractProbe as AbstractProbe
from .probe import CWProbe as CWProbe
from .probe import PointProbe as PointProbe
from .probe import PulsedProbe as PulsedProbe
from .probe import probe_for_spacing as probe_for_spacing
from .probe import probe_transfer as probe_transfer
from .progress import AbstractProgress as AbstractProgress
from .progress import CallbackProgress as CallbackProgress
from .progress import LineProgress as LineProgress
from .progress import NoProgress as NoProgress
from .progress import ProgressCallback as ProgressCallback
from .progress import ProgressTask as ProgressTask
from .progress import TextProgress as TextProgress
from .progress import TqdmProgress as TqdmProgress
from .progress import progress_meter as progress_meter
from .response import AbstractProfile as AbstractProfile
from .response import Instrument as Instrument
from .response import PeriodicSpline as PeriodicSpline
from .response import PowerLawProfile as PowerLawProfile
from .response import ProfileTable as ProfileTable
from .response import ResponseTable as ResponseTable
from .response import TableRuns as TableRuns
from .response import UniformProfile as UniformProfile
from .roses import CorrectionRose as CorrectionRose
from .roses import correction_rose as correction_rose
from .roses import sector_rose as sector_rose
from .scan import Scan as Scan
from .scan import nacelle_2beam as nacelle_2beam
from .scan import nacelle_4beam as nacelle_4beam
from .scan import nacelle_shear as nacelle_shear
from .scan import reconstruct as reconstruct
from .scan import six_beam as six_beam
from .scan import windcube_v1 as windcube_v1
from .scan import windcube_v2 as windcube_v2
from .scan import zephir as zephir
from .scanning import DUAL_ILL_CONDITIONED as DUAL_ILL_CONDITIONED
from .scanning import CrossingGeometry as CrossingGeometry
from .scanning import DualDoppler as DualDoppler
from .scanning import ScanPattern as ScanPattern
from .scanning import ScanResult as ScanResult
from .scanning import VadProfile as VadProfile
from .scanning import crossing_geometry as crossing_geometry
from .scanning import dual_doppler as dual_doppler
from .scanning import gate_nodes as gate_nodes
from .scanning import gate_ranges as gate_ranges
from .scanning import instrument_probe as instrument_probe
from .scanning import ppi as ppi
from .scanning import rhi as rhi
from .scanning import scan_points as scan_points
from .scanning import simulate_dual_doppler as simulate_dual_doppler
from .scanning import simulate_scan as simulate_scan
from .scanning import simulate_scan_series as simulate_scan_series
from .scanning import spinner_rosette as spinner_rosette
from .scanning import stare as stare
from .scanning import vad as vad
from .scanning import vad_fit as vad_fit
from .sensitivity import Budget as Budget
from .sensitivity import Sensitivity as Sensitivity
from .sensitivity import sensitivity as sensitivity
from .sensitivity import uncertainty as uncertainty
from .series import Series as Series
from .series import SeriesStatistics as SeriesStatistics
from .series import simulate_series as simulate_series
from .series import simulate_statistics as simulate_statistics
from .series import statistics as statistics
from .spectral import LidarGeometry as LidarGeometry
from .spectral import LidarVariance as LidarVariance
from .spectral import lidar_geometry as lidar_geometry
from .spectral import lidar_response as lidar_response
from .spectral import lidar_variance as lidar_variance
from .spectral import lidar_variance_ratio as lidar_variance_ratio
from .spectral import reconstruction_coefficients as reconstruction_coefficients
from .stresses import ReynoldsStresses as ReynoldsStresses
from .stresses import reynolds_stresses as reynolds_stresses
from .stresses import stress_matrix as stress_matrix
from .timing import Schedule as Schedule
from .timing import schedule_for as schedule_for
from .turbulence import TurbulenceBox as TurbulenceBox
from .turbulence import box_variance as box_variance
from .turbulence import box_wavenumbers as box_wavenumbers
from .turbulence import fft_mann_box as fft_mann_box
from .turbulence import mann_box as mann_box
from .turbulence import mann_eddy_lifetime as mann_eddy_lifetime
from .turbulence import mann_spectrum_level as mann_spectrum_level
from .turbulence import mann_tensor as mann_tensor
from .turbulence import synthesize_box as synthesize_box
from .workflows.demo import run_demo as run_demo
from .workflows.farm_study import FARM_SCANS as FARM_SCANS
from .workflows.farm_study import FarmStudy as FarmStudy
from .workflows.farm_study import FarmStudyConfig as FarmStudyConfig
from .workflows.farm_study import check_lidar_position as check_lidar_position
from .workflows.farm_study import farm_monitor_points as farm_monitor_points
from .workflows.farm_study import farm_study as farm_study
from .workflows.farm_study import write_farm_study as write_farm_study
from .workflows.joint_records import JointCorrected as JointCorrected
from .workflows.joint_records import correct_records_joint as correct_records_joint
from .workflows.monitor_points import MonitorPointField as MonitorPointField
from .workflows.monitor_points import MonitorPoints as MonitorPoints
from .workflows.monitor_points import monitor_points as monitor_points
from .workflows.monitor_points import simulate_from_monitor_points as simulate_from_monitor_points
from .workflows.records import DEFAULT_MIN_AVAILABILITY as DEFAULT_MIN_AVAILABILITY
from .workflows.records import CorrectedRecords as CorrectedRecords
from .workflows.records import RecordSet as RecordSet
from .workflows.records import check_instrument as check_instrument
from .workflows.records import correct_records as correct_records
from .workflows.records import load_records as load_records
from .workflows.records import match_heights as match_heights
from .workflows.records import quality_summary as quality_summary
from .workflows.records import reported_noise as reported_noise
from .workflows.records import tilt_difference as tilt_difference
from .workflows.records import write_corrected_csv as write_corrected_csv
from .workflows.records import write_corrected_netcdf as write_corrected_netcdf
from .workflows.seed_results import explain_nans as explain_nans
from .workflows.seed_results import seed_result_files as seed_result_files
from .workflows.seed_results import write_seed_results as write_seed_results
from .workflows.seed_tables import build_table as build_table
from .workflows.seed_tables import settings_mount as settings_mount
from .workflows.seed_tables import settings_mounts as settings_mounts
from .workflows.seed_tables import simulate_settings as simulate_settings
from .workflows.sensitivity_report import REPORT_OUTPUTS as REPORT_OUTPUTS
from .workflows.sensitivity_report import REPORT_SCANS as REPORT_SCANS
from .workflows.sensitivity_report import SensitivityReport as SensitivityReport
from .workflows.sensitivity_report import sensitivity_report as sensitivity_report
from .workflows.sensitivity_report import write_sensitivity_report as write_sensitivity_report
from .workflows.series_report import write_series_report as write_series_report
from .workflows.series_run import mean_wind_above as mean_wind_above
from .workflows.series_run import series_field as series_field
from .zephycube import NormalisedRose as NormalisedRose
from .zephycube import ZephyCubeWind as ZephyCubeWind
from .zephycube import beam_layout as beam_layout
from .zephycube import homogeneous_wind as homogeneous_wind
from .zephycube import normalised_rose as normalised_rose
from .zephycube import scalar_correction as scalar_correction
from .zephycube import vector_correction as vector_correction

__all__ = [
    "control", "FarmStudyConfig", "LacDesign", "design_lac_scan",
    "io", "plots", "scenes", "direction_difference", "heading", "horizontal_speed", "seed_azimuth",
    "wind_direction", "wrap180", "simulate_rotations", "stack_fields", "stack_mounts",
    "unstack_field", "unstack_mounts", "ExactPoints", "GradedProbe", "beam_points",
    "probe_for_field", "Calibration", "calibrate", "correction_factors", "DualDopplerDesign",
    "Placement", "RegionBox", "RegionPolygon", "RegionRing", "VadDesign", "design_dual_doppler",
    "design_placement", "design_vad", "dual_doppler_variance", "evaluate_placements",
    "placement_objective", "placement_problem", "vad_variance", "DisturbedSector",
    "disturbed_sectors", "excluded_width", "in_sectors", "merge_sectors", "AbstractField",
    "FieldSequence", "GridField", "SnapshotField", "BLOCKING_FLAGS", "MIN_AVAILABILITY", "Flag",
    "InverseFlag", "RecordFlag", "scan_bounds", "Simulation", "beam_gradient", "simulate",
    "beam_directions", "body_to_cfd_rotation", "cfd_to_lidar_rotation", "cfd_to_north_rotation",
    "lidar_to_cfd_rotation", "lidar_to_north_rotation", "rotate", "rotation_x", "rotation_y",
    "rotation_z", "tilt_rotation", "Inversion", "JointInversion", "invert", "invert_joint",
    "invert_joint_reconstructed", "invert_reconstructed", "AbstractMotion", "SampledMotion",
    "SinusoidalMotion", "Mount", "AbstractProbe", "CWProbe", "PointProbe", "PulsedProbe",
    "probe_for_spacing", "probe_transfer", "AbstractProgress", "CallbackProgress", "LineProgress",
    "NoProgress", "ProgressCallback", "ProgressTask", "TextProgress", "TqdmProgress",
    "progress_meter", "AbstractProfile", "Instrument", "PeriodicSpline", "PowerLawProfile",
    "ProfileTable", "ResponseTable", "TableRuns", "UniformProfile", "CorrectionRose",
    "correction_rose", "sector_rose", "Scan", "nacelle_2beam", "nacelle_4beam", "nacelle_shear",
    "reconstruct", "six_beam", "windcube_v1", "windcube_v2", "zephir", "DUAL_ILL_CONDITIONED",
    "CrossingGeometry", "DualDoppler", "ScanPattern", "ScanResult", "VadProfile",
    "crossing_geometry", "dual_doppler", "gate_nodes", "gate_ranges", "instrument_probe", "ppi",
    "rhi", "scan_points", "simulate_dual_doppler", "simulate_scan", "simulate_scan_series",
    "spinner_rosette", "stare", "vad", "vad_fit", "Budget", "Sensitivity", "sensitivity",
    "uncertainty", "Series", "SeriesStatistics", "simulate_series", "simulate_statistics",
    "statistics", "LidarGeometry", "LidarVariance", "lidar_geometry", "lidar_response",
    "lidar_variance", "lidar_variance_ratio", "reconstruction_coefficients", "ReynoldsStresses",
    "reynolds_stresses", "stress_matrix", "Schedule", "schedule_for", "TurbulenceBox",
    "box_variance", "box_wavenumbers", "fft_mann_box", "mann_box", "mann_eddy_lifetime",
    "mann_spectrum_level", "mann_tensor", "synthesize_box", "run_demo", "FARM_SCANS", "FarmStudy",
    "check_lidar_position", "farm_monitor_points", "farm_study", "write_farm_study",
    "JointCorrected", "correct_records_joint", "MonitorPointField", "MonitorPoints",
    "monitor_points", "simulate_from_monitor_points", "DEFAULT_MIN_AVAILABILITY",
    "CorrectedRecords", "RecordSet", "check_instrument", "correct_records", "load_records",
    "match_heights", "quality_summary", "reported_noise", "tilt_difference", "write_corrected_csv",
    "write_corrected_netcdf", "explain_nans", "seed_result_files", "write_seed_results",
    "build_table", "settings_mount", "settings_mounts", "simulate_settings", "REPORT_OUTPUTS",
    "REPORT_SCANS", "SensitivityReport", "sensitivity_report", "write_sensitivity_report",
    "write_series_report", "mean_wind_above", "series_field", "NormalisedRose", "ZephyCubeWind",
    "beam_layout", "homogeneous_wind", "normalised_rose", "scalar_correction", "vector_correction",
]

try:
    __version__ = importlib.metadata.version("lidarjax")
except importlib.metadata.PackageNotFoundError:  # running from a source tree
    __version__ = "0.0.0"

_deprecated.install()
__getattr__ = _deprecated.deprecated_getattr(__name__)
