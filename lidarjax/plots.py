"""Report figures (matplotlib is an optional extra: ``pip install lidarjax[plot]``).

Each function draws one figure, saves it to `path` (PNG unless the suffix says otherwise)
and returns the path. None of them is needed by the numerical core.
"""

from __future__ import annotations

from pathlib import Path

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .forward import simulate

__all__ = ["plot_profiles", "plot_los_fit", "plot_roses", "plot_sensitivity", "sensitivity_map",
           "plot_budget", "plot_sensitivity_profiles", "plot_series_ti", "plot_farm_map"]

_COLOURS = {"point": "k", "windcube_v1": "C0", "windcube_v2": "C1", "zephir": "C2"}
_LABELS = {"point": "point above the lidar", "windcube_v1": "Windcube V1",
           "windcube_v2": "Windcube V2", "zephir": "ZephIR"}


def _pyplot():
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError as err:  # pragma: no cover - depends on the environment
        raise ImportError(
            "lidarjax plots need matplotlib: pip install 'lidarjax[plot]'") from err
    return plt


def _save(fig, path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".part")
    fig.savefig(tmp, dpi=110, bbox_inches="tight", format=path.suffix.lstrip(".") or "png")
    tmp.replace(path)
    return path


def plot_profiles(z_over_h, c_u: dict, dtheta: dict, path, *, title=None) -> Path:
    """C_U = U / U_free and the direction error against z / H (seed 003, figure 4).

    **Arguments:** `z_over_h` ``(h,)``; `c_u` and `dtheta` map a name ('point',
    'windcube_v1', ...) to arrays ``(s, h)`` over inflow directions (the line is the mean,
    the band the range); `dtheta` in degrees.
    """
    plt = _pyplot()
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(10, 5), sharey=True)
    for name, values in c_u.items():
        col = _COLOURS.get(name, None)
        v = np.asarray(values)
        ax1.plot(v.mean(0), z_over_h, "-o", color=col, label=_LABELS.get(name, name), ms=4)
        ax1.fill_betweenx(z_over_h, v.min(0), v.max(0), color=col, alpha=0.12)
        d = np.asarray(dtheta[name])
        ax2.plot(d.mean(0), z_over_h, "-o", color=col, ms=4)
        ax2.fill_betweenx(z_over_h, d.min(0), d.max(0), color=col, alpha=0.12)
    ax1.axvline(1.0, color="0.6", lw=0.8)
    ax2.axvline(0.0, color="0.6", lw=0.8)
    ax1.set_xlabel("$C_U = U / U_{free}$")
    ax2.set_xlabel(r"$\Delta\theta = \theta_{free} - \theta$ (deg)")
    ax1.set_ylabel("z / H")
    ax1.legend(loc="best", fontsize=8)
    for ax in (ax1, ax2):
        ax.grid(alpha=0.3)
    fig.suptitle(title or "mean over inflow directions (band: range)")
    return _save(fig, path)


def plot_los_fit(azimuths, los, fitted_velocity, cone_angle, path, *, title=None) -> Path:
    """LOS against scan azimuth with the fitted sine (seed 003, figure 2).

    **Arguments:** `azimuths` ``(b,)`` degrees; `los` ``(b,)`` m/s; `fitted_velocity`
    ``(3,)`` the reconstructed ``(u, v, w)`` in the lidar frame; `cone_angle` degrees.
    The curve is ``u sin c sin a + v sin c cos a + w cos c``.
    """
    plt = _pyplot()
    a = np.linspace(0.0, 360.0, 361)
    c = np.radians(cone_angle)
    u, v, w = np.asarray(fitted_velocity)
    curve = u * np.sin(c) * np.sin(np.radians(a)) + v * np.sin(c) * np.cos(np.radians(a)) \
        + w * np.cos(c)
    fig, ax = plt.subplots(figsize=(7, 4))
    ax.plot(a, curve, "-", color="C0", label="fitted sine (reconstruction)")
    ax.plot(np.asarray(azimuths), np.asarray(los), "o", color="C3", ms=4, label="LOS in the flow")
    ax.set_xlabel("scan azimuth (deg, clockwise from lidar +y)")
    ax.set_ylabel("LOS velocity (m/s, + away)")
    ax.set_xlim(0, 360)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title(title or "ZephIR conical scan")
    return _save(fig, path)


def plot_roses(directions, speed_ratio, direction_addend, labels, path, *, title=None,
               shade=None, shade_label="disturbed sectors (IEC 61400-12-1 A)") -> Path:
    """Correction roses: speed ratio and direction addend against direction, polar axes.

    **Arguments:** `directions` ``(d,)`` meteorological degrees; `speed_ratio` and
    `direction_addend` ``(d, h)`` (addend in degrees); `labels` one per column ``h``;
    `shade`: optional ``(start, end)`` direction intervals in degrees (e.g. merged disturbed
    sectors from `lidarjax.disturbed_sectors.merge_sectors`) shaded grey on both roses.
    """
    plt = _pyplot()
    fig = plt.figure(figsize=(11, 5))
    th = np.radians(np.append(directions, directions[0]))
    for k, (data, name) in enumerate(((speed_ratio, "speed ratio U_free / U_lidar"),
                                      (direction_addend, "direction addend (deg)"))):
        ax = fig.add_subplot(1, 2, k + 1, projection="polar")
        ax.set_theta_zero_location("N")
        ax.set_theta_direction(-1)
        d = np.asarray(data)
        for j, lab in enumerate(labels):
            ax.plot(th, np.append(d[:, j], d[0, j]), lw=1.2, label=str(lab))
        lo, hi = np.nanmin(d), np.nanmax(d)
        pad = 0.1 * (hi - lo) if hi > lo else 0.01
        ax.set_rlim(lo - pad, hi + pad)  # the radial axis spans the data, not from zero
        for m, (a, b) in enumerate(shade or ()):
            tt = np.radians(np.linspace(a, b, max(int(b - a), 2) + 1))
            ax.fill_between(tt, lo - pad, hi + pad, color="0.6", alpha=0.35, lw=0,
                            label=shade_label if m == 0 else None)
        ax.set_title(name, fontsize=10, pad=18)
    fig.axes[0].legend(loc="lower left", bbox_to_anchor=(-0.25, -0.15), fontsize=7)
    fig.suptitle(title or "correction roses against inflow direction", y=1.04)
    return _save(fig, path)


def sensitivity_map(field, scan, mount, height, *, u_ref=None, probe=None):
    """Gradient of the lidar's horizontal-speed error with respect to the field values.

    The error is ``U_lidar - U_point`` at one `height` (m), or ``U_lidar - U_free`` with
    `u_ref`. Returns ``(nx, ny, nz)`` magnitudes ``|d error / d V_node|`` (per m/s of node
    velocity; dimensionless): which part of the flow drives the error.
    """

    def error(vel):
        f = eqx.tree_at(lambda fld: fld.velocity, field, vel)
        sim = simulate(f, scan, mount, jnp.atleast_1d(height), u_ref=u_ref, probe=probe,
                       point_reference=u_ref is None)
        ref = sim.free_speed if u_ref is not None else sim.point_speed[0]
        return sim.lidar_speed[0] - ref

    g = jax.grad(error)(field.velocity)
    return np.asarray(jnp.linalg.norm(g, axis=-1))


def plot_sensitivity(field, sensitivity, mount_location, height, path, *, title=None) -> Path:
    """Two slices of a `sensitivity_map`: horizontal at the lidar's measurement height and
    vertical through the lidar (summed over the other axis), in CFD metres."""
    plt = _pyplot()
    x, y, z = (np.asarray(a) for a in (field.x, field.y, field.z))
    s = np.asarray(sensitivity)
    iz = int(np.argmin(np.abs(z - (mount_location[2] + height))))
    fig, (ax1, ax2) = plt.subplots(1, 2, figsize=(11, 4.5))
    m1 = ax1.pcolormesh(x, y, s[:, :, iz].T, shading="auto", cmap="magma")
    ax1.plot(mount_location[0], mount_location[1], "c^", ms=8, label="lidar")
    ax1.set_aspect("equal")
    ax1.set_xlabel("x (m)")
    ax1.set_ylabel("y (m)")
    ax1.set_title(f"horizontal slice z = {z[iz]:.1f} m")
    ax1.legend(fontsize=8)
    fig.colorbar(m1, ax=ax1, label="|d(U_lidar - U_ref) / dV| per node")
    m2 = ax2.pcolormesh(x, z, s.sum(axis=1).T, shading="auto", cmap="magma")
    ax2.plot(mount_location[0], mount_location[2], "c^", ms=8)
    ax2.set_xlabel("x (m)")
    ax2.set_ylabel("z (m)")
    ax2.set_title("summed over y")
    fig.colorbar(m2, ax=ax2)
    fig.suptitle(title or "where the flow drives the lidar's speed error")
    return _save(fig, path)


def plot_budget(z_over_h, inputs, contributions: dict, std: dict, units: dict, path, *,
                title=None) -> Path:
    """Uncertainty budget bars per height: each input's contribution ``|c_i| u_i`` (one bar
    per input, log scale) and the combined standard uncertainty (black tick), one panel per
    output.

    **Arguments:** `z_over_h` ``(h,)``; `inputs` ``(p,)`` names; `contributions` maps an
    output name to ``(h, p)`` and `std` to ``(h,)`` (one sector; e.g. the largest over
    sectors), in the output's unit (`units[output]`).
    """
    plt = _pyplot()
    outs = list(contributions)
    p = len(inputs)
    fig, axes = plt.subplots(1, len(outs), figsize=(3.6 * len(outs) + 1.0, 0.32 * p *
                                                    len(z_over_h) ** 0.5 + 3.0), sharey=True,
                             squeeze=False)
    y = np.arange(len(z_over_h), dtype=float)
    width = 0.8 / p
    for ax, o in zip(axes[0], outs, strict=True):
        c = np.asarray(contributions[o], dtype=float)
        u = np.asarray(std[o], dtype=float)
        floor = max(np.nanmax(u), 1e-300) * 1e-6
        for i, name in enumerate(inputs):
            ax.barh(y - 0.4 + (i + 0.5) * width, np.maximum(c[:, i], floor), height=width,
                    color=f"C{i % 10}", label=name, left=0)
        ax.plot(u, y, "k|", ms=14, mew=2, label="combined u")
        ax.set_xscale("log")
        ax.set_xlim(left=floor * 10)
        ax.set_xlabel(f"{o} ({units[o]})")
        ax.grid(alpha=0.3, axis="x")
    axes[0][0].set_yticks(y)
    axes[0][0].set_yticklabels([f"{v:.2f}" for v in np.asarray(z_over_h)])
    axes[0][0].set_ylabel("z / H")
    axes[0][-1].legend(loc="center left", bbox_to_anchor=(1.02, 0.5), fontsize=8)
    fig.suptitle(title or "standard uncertainty contributions |c_i| u(x_i) per height")
    return _save(fig, path)


def plot_sensitivity_profiles(z_over_h, inputs, jacobian: dict, units: dict, path, *,
                              title=None) -> Path:
    """Sensitivity coefficients ``d output / d input`` against z / H: one row per output,
    one column per input; the line is the mean over sectors, the band their range.

    **Arguments:** `z_over_h` ``(h,)``; `inputs` ``(p,)`` names; `jacobian` maps an output to
    ``(s, h, p)``; `units` maps ``(output, input)`` to the unit text ('m/s per deg').
    """
    plt = _pyplot()
    outs = list(jacobian)
    p = len(inputs)
    fig, axes = plt.subplots(len(outs), p, figsize=(2.3 * p + 0.6, 2.2 * len(outs) + 0.6),
                             sharey=True, squeeze=False)
    z = np.asarray(z_over_h)
    for r, o in enumerate(outs):
        j = np.asarray(jacobian[o], dtype=float)
        for i, name in enumerate(inputs):
            ax = axes[r][i]
            ji = j[..., i]
            ax.plot(np.nanmean(ji, 0), z, "-o", ms=3, color=f"C{r}")
            ax.fill_betweenx(z, np.nanmin(ji, 0), np.nanmax(ji, 0), color=f"C{r}", alpha=0.15)
            ax.axvline(0.0, color="0.6", lw=0.8)
            ax.set_title(f"d {o} / d {name}", fontsize=8)
            ax.set_xlabel(units[(o, name)], fontsize=7)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3)
        axes[r][0].set_ylabel("z / H")
    fig.suptitle(title or "sensitivity profiles (mean over sectors, band: range)")
    fig.tight_layout()
    return _save(fig, path)
def plot_series_ti(heights, lidar_ti, cup_ti, sonic_ti, path, *, label="lidar", title=None) -> Path:
    """Lidar against point-sensor turbulence intensity: left, per record and height (one
    colour per height, the 1:1 line dashed); right, the mean profile of the lidar's, the
    cup's and the sonic's TI. Arrays ``(r, h)``, heights ``(h,)`` m."""
    plt = _pyplot()
    heights = np.asarray(heights)
    lidar_ti, cup_ti, sonic_ti = (np.asarray(a, float) for a in (lidar_ti, cup_ti, sonic_ti))
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 4.2))
    cmap = plt.get_cmap("viridis")
    for k, h in enumerate(heights):
        ax.scatter(100 * cup_ti[:, k], 100 * lidar_ti[:, k], s=8, alpha=0.6,
                   color=cmap(k / max(len(heights) - 1, 1)), label=f"{h:g} m")
    both = np.concatenate([cup_ti.ravel(), lidar_ti.ravel()])
    both = both[np.isfinite(both)]
    if both.size:
        lo, hi = 100 * both.min(), 100 * both.max()
        ax.plot([lo, hi], [lo, hi], "k--", lw=1)
    ax.set_xlabel("cup TI (%)")
    ax.set_ylabel(f"{label} TI (%)")
    ax.legend(fontsize=7, ncol=2, title="height")
    ax.set_title("per 10-minute record")
    for arr, name, style in ((lidar_ti, label, "o-"), (cup_ti, "cup", "s--"),
                             (sonic_ti, "sonic (longitudinal)", "^:")):
        bx.plot(100 * np.nanmean(arr, axis=0), heights, style, label=name)
    bx.set_xlabel("mean TI (%)")
    bx.set_ylabel("height above the lidar (m)")
    bx.legend(fontsize=8)
    bx.set_title("mean over records")
    if title:
        fig.suptitle(title)
    path = _save(fig, path)
    plt.close(fig)
    return path
def plot_farm_map(farm, height, path, *, names=None, lidar=None, beams=None, extent=None,
                  n=160, title=None) -> Path:
    """A plan view of a `lidarjax.scenes.WindFarm`'s speed at `height` m above its datum, with
    the rotors (lines across their axis), the lidar and its beams.

    **Arguments:** `farm`; `height` (m); `names` of the turbines; `lidar` ``(x, y)`` and
    `beams` ``(k, 2, 2)`` horizontal segments (start, end), local coordinates (m, relative to
    ``farm.origin``); `extent` ``(xmin, xmax, ymin, ymax)`` (default: the turbines, the
    lidar and the beams with a margin); `n` pixels per side.
    """
    plt = _pyplot()
    tx, ty = np.asarray(farm.x, np.float64), np.asarray(farm.y, np.float64)
    diam = np.asarray(farm.diameter, np.float64)
    if extent is None:
        xs = [tx, [lidar[0]] if lidar is not None else []]
        ys = [ty, [lidar[1]] if lidar is not None else []]
        if beams is not None:
            b = np.asarray(beams, np.float64)
            xs.append(b[..., 0].ravel())
            ys.append(b[..., 1].ravel())
        xx, yy = np.concatenate(xs), np.concatenate(ys)
        m = 3.0 * float(diam.max())
        extent = (xx.min() - m, xx.max() + m, yy.min() - m, yy.max() + m)
    gx = np.linspace(extent[0], extent[1], n)
    gy = np.linspace(extent[2], extent[3], n)
    pts = np.stack([*np.meshgrid(gx, gy, indexing="xy"), np.full((n, n), float(height))], -1)
    speed = np.asarray(jax.jit(lambda f, p: f.streamwise_local(p))(farm, jnp.asarray(pts, farm.dtype)))
    fig, ax = plt.subplots(figsize=(8, 7))
    im = ax.pcolormesh(gx, gy, speed, shading="auto", cmap="viridis")
    fig.colorbar(im, ax=ax, label=f"speed at {float(height):g} m (m/s)")
    heading = np.radians(np.asarray(farm.rotor_heading(), np.float64))
    across = np.stack([np.cos(heading), -np.sin(heading)], -1)  # perpendicular to the axis
    for k in range(tx.size):
        seg = np.array([[tx[k], ty[k]]]) + np.outer([-0.5, 0.5], across[k]) * diam[k]
        ax.plot(seg[:, 0], seg[:, 1], "w-", lw=2.5)
        if names is not None:
            ax.annotate(str(names[k]), (tx[k], ty[k]), color="w", fontsize=7,
                        xytext=(3, 3), textcoords="offset points")
    if beams is not None:
        for s in np.asarray(beams, np.float64):
            ax.plot(s[:, 0], s[:, 1], "r-", lw=0.8)
    if lidar is not None:
        ax.plot([lidar[0]], [lidar[1]], "r^", ms=8, label="lidar")
        ax.legend(loc="upper right", fontsize=8)
    ax.set_aspect("equal")
    ax.set_xlabel("easting - origin (m)")
    ax.set_ylabel("northing - origin (m)")
    ax.set_title(title or f"wake field from {float(farm.direction):g} deg at {float(height):g} m")
    return _save(fig, path)


def plot_design(placement, path, *, grid_xy=None, grid_values=None, title=None,
                outline=None) -> Path:
    """A placement design (`lidarjax.design_placement`): the objective over the region (the
    coarse stage's candidates, or `grid_xy` ``(m, 2)`` / `grid_values` ``(m,)`` of a finer
    map, NaN where infeasible), the start, the local search's path and the optimum (left);
    the speed correction ``C_U`` against the free-stream direction at the start and at the
    optimum, first and last height (right). `outline`: ``(n, 2)`` a polygon to draw."""
    plt = _pyplot()
    fig, (ax, rax) = plt.subplots(1, 2, figsize=(12, 5), gridspec_kw={"width_ratios": [1, 1.1]})
    names = list(placement.names)
    if grid_xy is None:
        grid_xy, grid_values = placement.coarse[:, :2], placement.coarse_values
    xy = np.asarray(grid_xy, np.float64)
    v = np.asarray(grid_values, np.float64)
    ok = np.isfinite(v)
    if ok.sum() >= 16:
        art = ax.tricontourf(xy[ok, 0], xy[ok, 1], v[ok], levels=24, cmap="viridis")
    else:
        art = ax.scatter(xy[ok, 0], xy[ok, 1], c=v[ok], s=30, cmap="viridis")
    if (~ok).any():
        ax.scatter(xy[~ok, 0], xy[~ok, 1], c="0.5", s=6, marker="x", label="infeasible")
    fig.colorbar(art, ax=ax, label="objective")
    if outline is not None:
        o = np.asarray(outline, np.float64)
        ax.plot(np.append(o[:, 0], o[0, 0]), np.append(o[:, 1], o[0, 1]), "k-", lw=0.8)
    p = np.asarray(placement.path)
    if p.size and p.shape[1] >= 2:
        ax.plot(p[:, 0], p[:, 1], "w.-", lw=1.0, ms=4, label="local search path")
        ax.plot(p[0, 0], p[0, 1], "o", mfc="none", mec="r", ms=9, label="start")
        ax.plot(placement.x[0], placement.x[1], "r*", ms=14, label="optimum")
    ax.set_xlabel(f"{names[0]} (m)")
    ax.set_ylabel(f"{names[1] if len(names) > 1 else ''} (m)")
    ax.set_aspect("equal", adjustable="datalim")
    ax.legend(fontsize=7, loc="lower right", framealpha=0.8)
    ax.set_title("objective over the region", fontsize=10)
    if placement.rose is not None and placement.rose_start is not None:
        for rose, style, lab in ((placement.rose_start, "--", "start"),
                                 (placement.rose, "-", "optimum")):
            d = np.asarray(rose.directions)
            r = np.asarray(rose.speed_ratio)
            for j in sorted({0, r.shape[1] - 1}):
                rax.plot(d, r[:, j], style, marker="o", ms=3, lw=1.2, color=f"C{j and 1}",
                         label=f"{lab}, height {j + 1} of {r.shape[1]}")
        rax.axhline(1.0, color="0.6", lw=0.8)
        rax.set_xlabel("free-stream direction (deg)")
        rax.set_ylabel("C_U = U_free / U_lidar")
        rax.set_xlim(-5, 365)
        rax.legend(fontsize=7)
        rax.set_title("speed correction at the start and at the optimum", fontsize=10)
    fig.suptitle(title or "lidar placement design")
    fig.tight_layout()
    return _save(fig, path)
