# ruff: noqa
# Recipe script as run for tests/data/openfoam (paths are those of the run; adapt them).
import jax
import numpy as np

jax.config.update("jax_enable_x64", True)
import lidarjax as lj
from lidarjax.workflows.monitor_points import monitor_points
from lidarjax.io.monitor_points import write_openfoam_probes, write_monitor_points_csv

scan = lj.windcube_v2()
roof = lj.Mount(np.array([96.0, 126.0, 39.0]), beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
street = lj.Mount(np.array([72.0, 66.0, 1.0]), beta=0.0, gamma=0.0, psi=0.0, epsilon=0.0)
hr = np.arange(10.0, 96.0, 5.0); hs = np.arange(10.0, 131.0, 5.0)
a = monitor_points(scan, roof, hr, labels=["roof"]); b = monitor_points(scan, street, hs, labels=["street"])
import dataclasses

locs = type(a)(**{f.name: (tuple(getattr(a, f.name)) + tuple(getattr(b, f.name)) if isinstance(getattr(a, f.name), tuple)
                            else np.concatenate([getattr(a, f.name), getattr(b, f.name)])) for f in dataclasses.fields(a)})
write_openfoam_probes("/work/f11_of/probes/lidarProbes", locs)
write_monitor_points_csv("/work/f11_of/probes/lidarProbes.csv", locs)
print(len(locs), locs.points.min(0), locs.points.max(0))
