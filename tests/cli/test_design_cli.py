"""`lidarjax design`: the committed OpenFOAM roof case (windAroundBuildings cut) through the
command line: best location as a settings.dat row, roses, objective map and figure; and
one-line errors for bad regions."""

import csv

import numpy as np
import pytest

from lidarjax.cli import main
from lidarjax.io import Settings, read_settings, write_settings

from ..helpers import DATA

CASE = DATA / "openfoam" / "windAroundBuildings_cut"
POLYGON = "polygon:90,120,96,120,96,132,90,132"  # the 38 m roof (no notch)


@pytest.fixture(scope="module")
def settings(tmp_path_factory):
    root = tmp_path_factory.mktemp("design_cli")
    write_settings(root / "settings.dat", Settings(
        zone=2, verbose=1, height=30.0, nh=3, gamma=0.0, beta=0.0, psi=0.0, epsilon=0.0,
        betas=np.array([0.0]), locations=np.array([[96.0, 126.0, 39.0]])))
    return root / "settings.dat"


def test_design_on_the_openfoam_roof(settings, tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(["design", str(settings), "--field", str(CASE), "--u-ref", "10,0,0",
               "--scan", "windcube_v2", "--region", POLYGON, "--height-above-surface", "1",
               "--spacing", "2", "--n-coarse", "16", "--n-starts", "2", "--max-steps", "15",
               "--map", "6", "--out", str(out)])
    assert rc == 0
    text = capsys.readouterr().out
    assert "best location (x, y)" in text and "forward simulations" in text
    best = read_settings(out / "settings_design.dat").location(0.0)
    assert 90.0 <= best[0] <= 96.0 and 120.0 <= best[1] <= 132.0
    # 1 m above the surface read from the grid's nodes (2 m apart: the roof edge is smeared)
    assert 37.5 <= best[2] <= 41.0
    with open(out / "roses.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 3 and {"cff_U_start", "cff_U"} <= set(rows[0])
    with open(out / "objective_map.csv") as fh:
        rows = list(csv.reader(fh))
    assert rows[0][:2] == ["x", "y"] and len(rows) == 1 + 36
    values = np.array([float(r[2]) for r in rows[1:]])
    assert np.isfinite(values).sum() >= 10
    import matplotlib  # noqa: F401  (the test extra brings it)
    assert (out / "design.png").stat().st_size > 10_000


@pytest.mark.parametrize("region, message", [
    ("box:100,90,120,130,39,39", "empty region"),
    ("box:500,510,120,130,39,39", "outside the mesh"),
    ("polygon:0,0,1,1,2,2", "zero area"),
])
def test_bad_regions_are_one_line_errors(settings, tmp_path, capsys, region, message):
    rc = main(["design", str(settings), "--field", str(CASE), "--u-ref", "10,0,0",
               "--region", region, "--spacing", "2", "--out", str(tmp_path)])
    err = capsys.readouterr().err
    assert rc == 2 and message in err and err.count("\n") == 1, err
