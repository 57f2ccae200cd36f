"""Shared by the CLI tests of a series over a mesh: the real windAroundBuildings cut with a
lidar on the roof, and a record of the regions `lidarjax series` reads its mean flow over."""

from __future__ import annotations

import numpy as np

from lidarjax.io import Settings, load_field, write_settings

from ..helpers import DATA

CASE = DATA / "openfoam" / "windAroundBuildings_cut"
ROOF = [96.0, 126.0, 39.0]  # a lidar on the roof, absolute CFD metres


def roof_settings(path, nh: int):
    """A settings.dat with the lidar on the roof and `nh` heights up to 10 m."""
    write_settings(path, Settings(zone=2, verbose=1, height=10.0, nh=nh, gamma=0.0, beta=0.0,
                                  psi=0.0, epsilon=0.0, betas=np.array([0.0]),
                                  locations=np.array([ROOF])))
    return path


def record_regions(monkeypatch) -> list:
    """The `region` of every mean flow `lidarjax series` loads from now on (None: all)."""
    import lidarjax.cli.series as series_cli

    regions = []

    def spy(path, **kw):
        regions.append(kw.get("region"))
        return load_field(path, **kw)

    monkeypatch.setattr(series_cli, "load_field", spy)
    return regions
