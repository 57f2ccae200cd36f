"""The old public names of lidarjax 0.1, kept for one release as deprecated aliases.

Each alias works as before and emits one `DeprecationWarning` naming its replacement.
Attributes go through a module-level ``__getattr__`` (`deprecated_getattr`); whole modules
that moved (``lidarjax.workflow`` -> ``lidarjax.workflows.seed_tables``) through a small
import hook limited to the names in `MOVED_MODULES`. Remove both in the next release.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

__all__: list[str] = []

#: Old module path -> new module path.
MOVED_MODULES = {
    "lidarjax.workflow": "lidarjax.workflows.seed_tables",
    "lidarjax.records": "lidarjax.workflows.records",
    "lidarjax.cfd_probes": "lidarjax.workflows.monitor_points",
    "lidarjax.demo": "lidarjax.workflows.demo",
    "lidarjax.sectors": "lidarjax.disturbed_sectors",
    "lidarjax.turbulence_box": "lidarjax.turbulence",
    "lidarjax.io.probes": "lidarjax.io.monitor_points",
}

#: Module -> {old attribute: "new.module:new_name"}.
MOVED_NAMES = {
    "lidarjax": {
        "simulate_sectors": "lidarjax.batch:simulate_rotations",
        "ProbeField": "lidarjax.workflows.monitor_points:MonitorPointField",
        "ProbeLocations": "lidarjax.io.monitor_points:MonitorPoints",
        "probe_locations": "lidarjax.workflows.monitor_points:monitor_points",
        "simulate_from_probes": "lidarjax.workflows.monitor_points:simulate_from_monitor_points",
        "write_series_sta": "lidarjax.io.sta:write_series_sta",
        "sectors": "lidarjax.disturbed_sectors",
    },
    "lidarjax.io": {
        "RecordFlag": "lidarjax.flags:RecordFlag",
        "BLOCKING_FLAGS": "lidarjax.flags:BLOCKING_FLAGS",
        "MIN_AVAILABILITY": "lidarjax.flags:MIN_AVAILABILITY",
        "read_probe_csv": "lidarjax.io.monitor_points:read_monitor_points_csv",
        "write_probe_csv": "lidarjax.io.monitor_points:write_monitor_points_csv",
        "read_probe_values_csv": "lidarjax.io.monitor_points:read_monitor_values_csv",
        "seed_azimuth": "lidarjax.io.seed_output:_seed_azimuth_uv",
    },
    "lidarjax.scenes": {
        "heading": "lidarjax.angles:heading",
        "TurbulenceBox": "lidarjax.turbulence:TurbulenceBox",
        "mann_box": "lidarjax.turbulence:mann_box",
    },
    "lidarjax.scenes.turbulence": {
        "TurbulenceBox": "lidarjax.turbulence:TurbulenceBox",
        "mann_box": "lidarjax.turbulence:mann_box",
    },
    "lidarjax.spectral": {
        "probe_transfer": "lidarjax.probe:probe_transfer",
        "mann_tensor": "lidarjax.turbulence:mann_tensor",
        "mann_eddy_lifetime": "lidarjax.turbulence:mann_eddy_lifetime",
        "box_wavenumbers": "lidarjax.turbulence:box_wavenumbers",
        "box_variance": "lidarjax.turbulence:box_variance",
        "synthesize_box": "lidarjax.turbulence:synthesize_box",
    },
    "lidarjax.series": {
        "write_series_sta": "lidarjax.io.sta:write_series_sta",
        "write_series_report": "lidarjax.workflows.series_report:write_series_report",
    },
    "lidarjax.zephycube": {
        "Wind": "lidarjax.zephycube:ZephyCubeWind",
        "homogeneous": "lidarjax.zephycube:homogeneous_wind",
    },
}


def _resolve(target: str):
    module, _, name = target.partition(":")
    obj = importlib.import_module(module)
    return getattr(obj, name) if name else obj


def _public(target: str) -> str:
    module, _, name = target.partition(":")
    if not name:
        return module
    return f"{module}.{name}"


def warn(old: str, new: str, stacklevel: int = 3) -> None:
    warnings.warn(f"{old} is deprecated and will be removed in the next release; use {new}",
                  DeprecationWarning, stacklevel=stacklevel)


def deprecated_getattr(module: str):
    """A module ``__getattr__`` serving the old names of `module` with a warning."""
    table = MOVED_NAMES[module]

    def __getattr__(name: str):
        if name in table:
            warn(f"{module}.{name}", _public(table[name]))
            return _resolve(table[name])
        raise AttributeError(f"module {module!r} has no attribute {name!r}")

    return __getattr__


class _Alias(types.ModuleType):
    """Stands for a moved module: every attribute is the new module's."""

    def __init__(self, old: str, new: str):
        super().__init__(old)
        self.__dict__["_target"] = new

    def __getattr__(self, name: str):
        return getattr(importlib.import_module(self.__dict__["_target"]), name)

    def __dir__(self):
        return dir(importlib.import_module(self.__dict__["_target"]))


class _Loader(importlib.abc.Loader):
    def create_module(self, spec):
        new = MOVED_MODULES[spec.name]
        warn(f"module {spec.name}", new, stacklevel=8)
        importlib.import_module(new)
        return _Alias(spec.name, new)

    def exec_module(self, module):
        pass


class _Finder(importlib.abc.MetaPathFinder):
    def find_spec(self, fullname, path, target=None):
        if fullname in MOVED_MODULES:
            return importlib.util.spec_from_loader(fullname, _Loader())
        return None


def install() -> None:
    """Serve the moved modules (idempotent)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.append(_Finder())
