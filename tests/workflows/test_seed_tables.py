"""build_table at scale: one run in memory at a time (cropped to where the beams look), and
the same table from a Dask cluster."""

import functools
import gc
import tracemalloc
import weakref

import numpy as np
import pytest

import lidarjax as lj
from lidarjax.io import Settings, load_field, save_field_npz
from lidarjax.workflows.seed_tables import build_table, table_region

BETAS = [0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0]
SETTINGS = Settings(zone=2, verbose=1, height=30.0, nh=3, gamma=5.0, beta=0.0, psi=180.0,
                    epsilon=21.0, betas=np.array(BETAS), locations=np.tile([2.0, 1.0, 20.5], (8, 1)))
SCAN = lj.windcube_v2()
X = np.linspace(-60, 60, 41)
Z = np.linspace(0, 70, 15)


@functools.cache
def _velocity(beta):
    grid = lj.GridField.from_function(lj.scenes.hemisphere(20.0, 15.0, 90.0 + beta).sample, X, X, Z)
    return np.asarray(grid.velocity)


def run_field(beta):
    """A fresh GridField of the run at `beta` (its own device arrays on every call)."""
    return lj.GridField(X, X, Z, _velocity(beta))


class Tracker:
    """Loads runs and records how many full-size runs were alive at each load."""

    def __init__(self):
        self.refs = []
        self.max_alive = 0

    def __call__(self, beta):
        alive = sum(r() is not None for r in self.refs)
        if alive:  # held only by reference cycles? (a full collection takes ~1 s here)
            gc.collect()
            alive = sum(r() is not None for r in self.refs)
        self.max_alive = max(self.max_alive, alive + 1)
        f = run_field(beta)
        self.refs.append(weakref.ref(f))
        return f


@pytest.fixture(scope="module")
def serial():
    tracker = Tracker()
    table, sims = build_table(SETTINGS, BETAS, tracker, SCAN, progress=True)
    return tracker, table, sims


def test_one_run_at_a_time_and_same_results_as_full_fields(serial, capsys):
    tracker, table, sims = serial
    assert tracker.max_alive == 1
    from lidarjax.workflows.seed_tables import settings_mounts

    mounts = settings_mounts(SETTINGS, BETAS)
    for b, m in zip(BETAS, mounts, strict=True):
        full = lj.simulate(run_field(b), SCAN, m, SETTINGS.heights(), u_ref=[-15.0, 0.0, 0.0])
        np.testing.assert_array_equal(np.asarray(sims[b].los), np.asarray(full.los))  # crop: bit-exact
    lo, hi = table_region(SETTINGS, BETAS, SCAN)
    assert np.all(lo > X[0]) and np.all(hi < [X[-1], X[-1], Z[-1]])


def test_progress_lines(tmp_path, capsys):
    build_table(SETTINGS, BETAS[:3], run_field, SCAN, progress=True)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 3 and err[0].startswith("table: run 1/3 beta 0: grid (41, 41, 15) -> crop (")


def test_peak_memory_does_not_grow_with_runs(tmp_path):
    for b in BETAS:
        save_field_npz(tmp_path / f"run_{int(b)}.npz", run_field(b))

    def peak(betas):
        gc.collect()
        tracemalloc.start()
        build_table(SETTINGS, betas, lambda b: load_field(tmp_path / f"run_{int(b)}.npz"), SCAN)
        p = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
        return p

    one_run = X.size * X.size * Z.size * 3 * 8
    p3, p8 = peak(BETAS[:3]), peak(BETAS)
    assert p8 < 1.25 * p3 and p8 < 4 * one_run, (p3, p8, one_run)


def test_dask_cluster_gives_the_identical_table(serial):
    import distributed
    _, table, _ = serial
    # scheduler HTTP server on a free port: 8787 may be held by another test's cluster
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=False,
                                  dashboard_address=None, scheduler_kwargs={"dashboard_address": ":0"}
                                  ) as cluster, distributed.Client(cluster) as client:
        tracker = Tracker()
        dtable, _ = build_table(SETTINGS, BETAS, tracker, SCAN, client=client)
    assert tracker.max_alive <= 2  # one per worker
    np.testing.assert_array_equal(np.asarray(dtable.response), np.asarray(table.response))
    np.testing.assert_array_equal(np.asarray(dtable.directions), np.asarray(table.directions))
