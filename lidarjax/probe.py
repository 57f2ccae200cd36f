"""Probe volumes: how a lidar weights the wind along its beam around the focus range.

A probe turns the focus range ``f`` (m, along a beam) into quadrature nodes: offsets ``o_q``
along the beam (m, positive away from the lidar) and weights ``w_q`` summing to one; the LOS
is ``sum_q w_q n . V(x_lidar + (f + o_q) n)``. `PointProbe` samples at the focus only and
compiles no quadrature at all.
"""

from __future__ import annotations

import equinox as eqx

__all__ = ["AbstractProbe", "PointProbe"]


class AbstractProbe(eqx.Module):
    """Interface of a probe volume: ``nodes(focus_range) -> (offsets, weights)``."""

    def nodes(self, focus_range):
        """Quadrature ``(offsets (..., q) in m, weights (..., q))`` for ranges ``(...)`` in m."""
        raise NotImplementedError


class PointProbe(AbstractProbe):
    """An ideal point measurement at the focus range (the seed UDF's model)."""

    def nodes(self, focus_range):  # pragma: no cover - never traced: simulate skips it
        raise TypeError("PointProbe has no quadrature; simulate samples the focus point only.")
