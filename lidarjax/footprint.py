"""Where a lidar looks: the box of CFD space a scan touches, for cropping big fields.

`scan_bounds` gives the axis-aligned box (absolute CFD coordinates) that holds every point
`lidarjax.simulate` samples for a scan, mount(s) (tilt included), heights and probe: each beam's probe
nodes from ``f - reach`` to ``f + reach`` with ``reach = min(max |offset|, f)`` (nodes
beyond the probe's cut at the lidar get no weight, so they need no field) and, with
``point_reference=True``, the column above the lidar. `lidarjax.GridField.crop` then keeps
those cells plus a one-cell interpolation margin on each side, and results on the crop
equal the full field's bit for bit:

```python
lo, hi = lidarjax.scan_bounds(scan, mounts, heights, probe=probe)
small = field.crop(lo, hi)          # e.g. 96 MB -> a few hundred kB
```
"""

from __future__ import annotations

from collections.abc import Sequence

import jax
import numpy as np
from jaxtyping import ArrayLike, Float

from ._precision import is_concrete
from .frames import body_to_cfd_rotation
from .mount import Mount
from .probe import AbstractProbe, PointProbe
from .scan import Scan

__all__ = ["scan_bounds"]


def _mount_list(mounts) -> list[Mount]:
    if isinstance(mounts, Mount):
        if mounts.location.ndim == 2:  # stacked
            n = mounts.location.shape[0]
            return [jax.tree_util.tree_map(lambda x, k=k: x[k], mounts) for k in range(n)]
        return [mounts]
    return list(mounts)


def scan_bounds(
    scan: Scan,
    mounts: Mount | Sequence[Mount],
    heights: Float[ArrayLike, " h"],
    probe: AbstractProbe | None = None,
    *,
    point_reference: bool = True,
) -> tuple[np.ndarray, np.ndarray]:
    """The box ``(lo, hi)`` (absolute CFD coordinates, float64 ``(3,)`` each) that a scan
    samples.

    **Arguments:**

    - `scan`, `heights`, `probe`, `point_reference`: as given to `lidarjax.simulate`.
    - `mounts`: one `Mount`, a list, or a stacked `Mount` (the union of their boxes, e.g.
      all sectors of `lidarjax.simulate_rotations`).

    The box is tight (no margin): `lidarjax.GridField.crop` adds the interpolation margin.
    Needs concrete numbers (call it outside `jax.jit`).
    """
    if probe is None:
        probe = PointProbe()
    if not is_concrete(scan, heights, probe):
        raise ValueError("scan_bounds: needs concrete scan, heights and probe (not traced).")
    h = np.atleast_1d(np.asarray(heights, dtype=np.float64))
    n_lidar = np.asarray(scan.directions(), dtype=np.float64)  # (b, 3)
    ranges = h[:, None] / n_lidar[None, :, 2]  # (h, b)
    if isinstance(probe, PointProbe):
        near, far = ranges, ranges
    else:
        # the probe's whole support, cut at the lidar: covers its nodes at any node count
        # (`simulate` may choose more for the field's resolution)
        reach = np.minimum(np.asarray(probe.support(ranges), np.float64), ranges)
        near, far = ranges - reach, ranges + reach
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for mount in _mount_list(mounts):
        if not is_concrete(mount):
            raise ValueError("scan_bounds: needs concrete mounts (not traced).")
        loc = np.asarray(mount.location, np.float64) + np.asarray(mount.location_lo, np.float64)
        rot = np.asarray(body_to_cfd_rotation(mount), np.float64)
        n_cfd = n_lidar @ rot.T  # (b, 3)
        pts = [loc + r[..., None] * n_cfd for r in (near, far)]
        if point_reference:
            pts.append(loc + h[:, None] * np.array([0.0, 0.0, 1.0]))
        pts = np.concatenate([p.reshape(-1, 3) for p in pts])
        lo = np.minimum(lo, pts.min(axis=0))
        hi = np.maximum(hi, pts.max(axis=0))
    return lo, hi
