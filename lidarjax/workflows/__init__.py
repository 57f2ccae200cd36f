"""Workflows: files in, files out, built on the core, the scenes and `lidarjax.io`.

- `seed_tables`: the seed UDF's job: `simulate_settings` (one CFD run per platform rotation
  of a ``settings.dat``), `build_table` (a `lidarjax.ResponseTable` from CFD runs).
- `records`: real lidar records end to end: `load_records`, `check_instrument`,
  `correct_records`, `write_corrected_csv`, `write_corrected_netcdf`.
- `monitor_points`: the CFD code samples the beams itself: `monitor_points` lists the points,
  `simulate_from_monitor_points` runs the forward model on what the CFD code sampled.
- `seed_results`: the seed workflow's result files (`write_seed_results`: seed ``.dat``,
  CSV, NetCDF per beta) and `explain_nans` (why results are NaN, in one line).
- `sensitivity_report`: installation uncertainty budgets of a ``settings.dat``'s lidar over
  its platform rotations (`sensitivity_report` -> `SensitivityReport`,
  `write_sensitivity_report`: CSV per output, budget and sensitivity figures).
- `series_run`: the field of a simulated series: frozen turbulence over a mean flow
  (`series_field`, `mean_wind_above`).
- `series_report`: a simulated series' ``.sta``, statistics CSV and figure.
- `farm_study`: a lidar in a wind farm over many directions (`farm_study`, configured by
  `FarmStudyConfig` -> `FarmStudy`:
  wakes, correction factors, IEC disturbed sectors, yaw gradients, response table,
  `farm_monitor_points`; `write_farm_study`: the files of ``lidarjax farm``).
- `demo`: the built-in job of ``lidarjax demo`` (`run_demo`).

Each public name is also ``lidarjax.<name>``.
"""
