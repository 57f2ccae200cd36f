"""Draw ``docs/images/frame-chain.png``, the picture of lidarjax's frames on the Conventions
page: ``python tools/docs/frame_chain.py`` (matplotlib).

Left, seen from above: the CFD frame (the field's x, y), the lidar frame turned by
``beta + gamma - psi`` (beam S0 along its +y, S1 along its +x, clockwise seen from above), the
north frame turned by ``epsilon``, and a wind from the meteorological direction ``d``
(clockwise from north, where it comes from). Right, from the side: the cone angle ``c``, the
focus at range ``h / cos c``, LOS positive away from the lidar, and the body frame tilted by
``pitch`` (positive raises the S0 side).
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

OUT = Path(__file__).resolve().parents[2] / "docs" / "images" / "frame-chain.png"


def _arrow(ax, start, end, color, label=None, text_at=1.12, **kw):
    ax.annotate("", xy=end, xytext=start,
                arrowprops=dict(arrowstyle="-|>", color=color, lw=kw.pop("lw", 2), **kw))
    if label:
        p = np.asarray(start) + text_at * (np.asarray(end) - np.asarray(start))
        ax.text(*p, label, color=color, ha="center", va="center", fontsize=11)


def _rot(deg):
    """Anticlockwise rotation by `deg` (the convention of lidarjax.frames.rotation_z)."""
    t = np.radians(deg)
    return np.array([[np.cos(t), -np.sin(t)], [np.sin(t), np.cos(t)]])


def top_view(ax):
    ax.set_title("seen from above", fontsize=12)
    o = np.zeros(2)
    _arrow(ax, o, (1.0, 0.0), "0.3", "$x$ (CFD)")
    _arrow(ax, o, (0.0, 1.0), "0.3", "$y$ (CFD)")
    turn = 30.0  # the lidar frame: beam S0 turned clockwise from +y by beta + gamma - psi
    r = _rot(-turn)
    for k, name in enumerate(("S0", "S1", "S2", "S3")):
        d = r @ _rot(-90.0 * k) @ np.array([0.0, 0.8])
        _arrow(ax, o, d, "tab:blue", name, text_at=1.18, lw=1.6)
    a = np.linspace(90.0, 90.0 - turn, 30)
    ax.plot(0.45 * np.cos(np.radians(a)), 0.45 * np.sin(np.radians(a)), color="tab:blue", lw=1)
    ax.text(0.17, 0.52, r"$\beta+\gamma-\psi$", color="tab:blue", fontsize=10)
    eps = -15.0  # north: R(-epsilon) from the lidar frame
    north = r @ _rot(-eps) @ np.array([0.0, 1.15])
    _arrow(ax, o, north, "tab:green", "N", text_at=1.08, lw=1.4, linestyle="--")
    ax.text(*(0.9 * north + np.array([0.1, 0.0])), r"north: $R(-\epsilon)$", color="tab:green",
            fontsize=10)
    d = 250.0  # a wind from 250 degrees, clockwise from north
    nvec = north / np.linalg.norm(north)
    frm = _rot(-d) @ nvec
    _arrow(ax, 1.1 * frm, 0.35 * frm, "tab:red", None, lw=2.2)
    ax.text(*(1.2 * frm), f"wind from\n$d$ = {d:.0f}°", color="tab:red", ha="center", fontsize=10)
    ax.text(-1.3, -1.25, "angles in degrees; rotations about $z$ anticlockwise-positive;\n"
            "azimuths and directions clockwise seen from above", fontsize=8.5, color="0.25")
    ax.set_xlim(-1.4, 1.4)
    ax.set_ylim(-1.35, 1.4)
    ax.set_aspect("equal")
    ax.axis("off")


def side_view(ax):
    ax.set_title("from the side (beams S2 and S0)", fontsize=12)
    c = np.radians(28.0)
    h = 1.0
    o = np.zeros(2)
    ax.plot([-0.9, 0.9], [0, 0], color="0.6", lw=1)
    for sign, name in ((1, "S0"), (-1, "S2")):
        f = np.array([sign * h * np.tan(c), h])
        ax.plot(*zip(o, f, strict=True), color="tab:blue", lw=1.6)
        ax.plot(*f, "o", color="tab:blue")
        ax.text(f[0] + sign * 0.08, f[1] + 0.05, name, color="tab:blue", fontsize=11)
    f = np.array([h * np.tan(c), h])
    _arrow(ax, 0.55 * f, 0.75 * f, "tab:purple", None, lw=2)
    ax.text(0.75 * f[0] + 0.1, 0.62 * f[1], "LOS > 0\naway from\nthe lidar", color="tab:purple",
            fontsize=9)
    ax.plot([0, 0], [0, 1.15], color="0.3", lw=1, linestyle=":")
    a = np.linspace(90.0, 90.0 - np.degrees(c), 20)
    ax.plot(0.3 * np.cos(np.radians(a)), 0.3 * np.sin(np.radians(a)), color="0.3", lw=1)
    ax.text(0.04, 0.34, "$c$", fontsize=11)
    ax.annotate("", xy=(-0.75, h), xytext=(-0.75, 0),
                arrowprops=dict(arrowstyle="<->", color="0.3"))
    ax.text(-0.82, 0.5, "$h$", ha="right", fontsize=11)
    ax.text(0.62, 0.95, r"focus at range $h/\cos c$", fontsize=9, ha="left")
    tilt = np.radians(8.0)
    body = np.array([-np.sin(tilt), np.cos(tilt)]) * 0.55
    _arrow(ax, (0.0, 0.0), body, "tab:orange", None, lw=1.6)
    ax.text(0.12, -0.45, "body $z$, tilted by pitch\n(positive raises the S0 side;\n"
            r"$T = R_x(\mathrm{pitch})\,R_y(\mathrm{roll})$)", color="tab:orange", fontsize=9)
    ax.set_xlim(-1.0, 1.3)
    ax.set_ylim(-0.65, 1.25)
    ax.set_aspect("equal")
    ax.axis("off")


def main():
    fig, (a, b) = plt.subplots(1, 2, figsize=(10.5, 5.0))
    top_view(a)
    side_view(b)
    fig.suptitle("lidarjax's frame chain: CFD -> lidar -> north (and body -> lidar for a tilted mount)",
                 fontsize=12)
    fig.tight_layout()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(OUT, dpi=110)
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
