"""Shared tolerances and checks for the lidarjax tests."""

from __future__ import annotations

import os
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

RTOL64 = 1e-12
ATOL64 = 1e-12

#: The test tree, its committed data and the repository root.
TESTS = Path(__file__).resolve().parent
DATA = TESTS / "data"
REPO = TESTS.parent


def windcube_folder() -> Path | None:
    """The real Windcube files (`../shared/data/windcube/`; `LIDARJAX_WINDCUBE_DATA` wins), or
    None when this checkout has none beside it (main checkout or a worktree one level down)."""
    env = os.environ.get("LIDARJAX_WINDCUBE_DATA")
    if env:
        return Path(env)
    for base in (REPO.parent, REPO.parent.parent):
        folder = base / "shared" / "data" / "windcube"
        if folder.is_dir():
            return folder
    return None


def windcube_file(name: str) -> Path:
    """One real Windcube file, or skip the test naming it when the data are absent."""
    folder = windcube_folder()
    if folder is None or not (folder / name).is_file():
        pytest.skip(f"real Windcube data not available ({name})")
    return folder / name


#: Real scanning-lidar files the project commits (obtained from a package registry with
#: their licence): tests/data/scanning/.
SCANNING = DATA / "scanning"


def scanning_file(name: str) -> Path:
    """A real scanning-lidar file: committed in `SCANNING`, else (cuts of public repositories
    that this project may not commit, see tests/data/scanning/README.md) from
    `LIDARJAX_SCANNING_DATA` or ``../shared/data/scanning/``; skip the test naming it when
    absent."""
    if (SCANNING / name).is_file():
        return SCANNING / name
    places = [Path(os.environ["LIDARJAX_SCANNING_DATA"])] if os.environ.get("LIDARJAX_SCANNING_DATA") else []
    places += [base / "shared" / "data" / "scanning" for base in (REPO.parent, REPO.parent.parent)]
    for folder in places:
        if (folder / name).is_file():
            return folder / name
    pytest.skip(f"real scanning-lidar file not available ({name}: tests/data/scanning/README.md)")


#: The 2-ray Soverato VAD as the source repository holds it (its header says 6 rays per scan).
VAD_SOURCE = "VAD_194_20210624_170110.hpl"


def vad_cut(folder: Path, n_gates: int = 40) -> Path:
    """The committed recipe of the VAD cut (tests/data/scanning/README.md), run on the
    unedited source: every line kept byte for byte (CRLF, trailing spaces) except the
    gate lines past `n_gates` of each ray, dropped, and the header's ``Number of gates``,
    set to `n_gates`; ``No. of rays in file`` stays 6 (rays per scan; the file holds 2).
    Written into `folder` as ``VAD_194_20210624_170110_cut.hpl``."""
    source = scanning_file(VAD_SOURCE).read_bytes()
    lines = source.split(b"\r\n")
    end = next(i for i, line in enumerate(lines) if line.startswith(b"****"))
    head = [line.replace(b"Number of gates:\t400", b"Number of gates:\t%d" % n_gates)
            for line in lines[:end + 1]]
    body, k = [], end + 1
    while k < len(lines) and lines[k].strip():
        body += lines[k:k + 1 + n_gates]  # the ray line and its first gates
        k += 1 + 400
    out = folder / "VAD_194_20210624_170110_cut.hpl"
    out.write_bytes(b"\r\n".join(head + body + lines[k:]))
    return out


def _e_halo(x: float) -> str:
    """``x`` as the StreamLine writes beta: ``1.569249E-6`` (no zero-padded exponent)."""
    mantissa, exponent = f"{x:.6E}".split("E")
    return f"{mantissa}E{int(exponent)}"


def write_hpl(path: Path, *, hours, azimuth, elevation, doppler, intensity=None, beta=None,
              gate_length: float = 30.0, rays_per_scan: int = 1, scan_type: str = "Stare",
              start: str | None = None, system_id: str = "99", pitch_roll: bool = True,
              spectral_width=None, newline: str = "\r\n") -> Path:
    """Write a synthetic Halo ``.hpl`` in the real layout (header lines, fixed formats and
    CRLF line ends of the StreamLine files in ../shared/data/scanning): per ray the decimal
    hours `hours` ``(r,)`` (written modulo 24, as the instrument does), `azimuth`,
    `elevation` ``(r,)`` degrees, `doppler` ``(r, g)`` m/s, `intensity` (default 1.1) and
    `beta` (default 1e-6) ``(r, g)``; ``pitch roll`` 0.1 and -0.2 unless `pitch_roll` is
    False (the older three-number ray lines); a spectral-width column when given. The
    header's start time defaults to the first ray's time (start date 2024-03-01)."""
    hours = np.asarray(hours, float)
    doppler = np.asarray(doppler, float)
    r, g = doppler.shape
    intensity = np.full((r, g), 1.1) if intensity is None else np.asarray(intensity, float)
    beta = np.full((r, g), 1e-6) if beta is None else np.asarray(beta, float)
    if start is None:
        h = hours[0]
        start = f"20240301 {int(h):02d}:{int(h * 60) % 60:02d}:{(h * 3600) % 60:05.2f}"
    width = spectral_width is not None
    header = [
        f"Filename:\t{path.name}", f"System ID:\t{system_id}", f"Number of gates:\t{g}",
        f"Range gate length (m):\t{gate_length:.1f}", "Gate length (pts):\t10", "Pulses/ray:\t15000",
        f"No. of rays in file:\t{rays_per_scan}", f"Scan type:\t{scan_type}", "Focus range:\t65535",
        f"Start time:\t{start}", "Resolution (m/s):\t0.0382",
        "Range of measurement (center of gate) = (range gate + 0.5) * Gate length",
        "Data line 1: Decimal time (hours)  Azimuth (degrees)  Elevation (degrees)"
        + (" Pitch (degrees) Roll (degrees)" if pitch_roll else ""),
        "f9.6,1x,f6.2,1x,f6.2",
        "Data line 2: Range Gate  Doppler (m/s)  Intensity (SNR + 1)  Beta (m-1 sr-1)"
        + (" Spectral Width" if width else ""),
        "i3,1x,f6.4,1x,f8.6,1x,e12.6" + (",1x,f6.4" if width else "") + " - repeat for no. gates",
        "****" + (" Instrument spectral width = 5.656623" if width else ""),
    ]
    body = []
    for k in range(r):
        line = f"{hours[k] % 24:.8f} {azimuth[k]:6.2f} {elevation[k]:6.2f}"
        body.append(line + (" 0.10 -0.20" if pitch_roll else ""))
        for j in range(g):
            row = f"{j:3d} {doppler[k, j]:.4f} {intensity[k, j]:.6f} {_e_halo(beta[k, j]):>12}"
            body.append(row + (f" {spectral_width[k, j]:.4f}" if width else ""))
    path.write_text(newline.join(header + body) + newline, newline="")
    return path


def tree_allclose(a, b, rtol=RTOL64, atol=ATOL64) -> bool:
    """True when two pytrees have the same structure and all leaves are close (NaN == NaN)."""
    la, ta = jax.tree_util.tree_flatten(a)
    lb, tb = jax.tree_util.tree_flatten(b)
    if ta != tb:
        return False
    return all(
        np.allclose(np.asarray(x), np.asarray(y), rtol=rtol, atol=atol, equal_nan=True)
        for x, y in zip(la, lb, strict=True)
    )


def central_difference(f, x, eps=1e-6):
    """Centred finite-difference gradient of scalar `f` at array `x` (float64)."""
    x = np.asarray(x, dtype=np.float64)
    g = np.zeros_like(x)
    for idx in np.ndindex(x.shape):
        dx = np.zeros_like(x)
        dx[idx] = eps
        g[idx] = (float(f(jnp.asarray(x + dx))) - float(f(jnp.asarray(x - dx)))) / (2 * eps)
    return g


def assert_grad_matches_fd(f, x, eps=1e-6, rtol=1e-6, atol=1e-8, jit=False):
    """Reverse-mode, forward-mode and centred finite differences agree, and are finite. With
    `jit`, each derivative is one compiled function (taken eagerly, the jit calls inside `f`
    compile once more per transformation: a reverse-mode forward pass and its transpose); not
    for an `f` that needs concrete values before its own jit (`simulate_scan`). Returns the
    reverse-mode gradient function it checked (compiled with `jit`), for more points."""
    x = jnp.asarray(x, dtype=jnp.float64)
    wrap = jax.jit if jit else (lambda g: g)
    grad = wrap(jax.grad(f))
    g_rev = np.asarray(grad(x))
    g_fwd = np.asarray(wrap(jax.jacfwd(f))(x))
    g_fd = central_difference(f, x, eps)
    assert np.all(np.isfinite(g_rev)), g_rev
    np.testing.assert_allclose(g_rev, g_fwd, rtol=1e-10, atol=1e-12)
    np.testing.assert_allclose(g_rev, g_fd, rtol=rtol, atol=atol)
    return grad
