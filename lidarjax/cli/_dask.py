"""Scale-out options of the commands that read many CFD runs: a Dask cluster and the region
each run is read in."""

from __future__ import annotations

import contextlib
import inspect

import jax

from .._util import import_optional


def add_dask_arguments(parser) -> None:
    """``--workers N`` (a local Dask cluster) and ``--scheduler ADDRESS`` (an existing one)."""
    group = parser.add_mutually_exclusive_group()
    group.add_argument("--workers", type=int, default=None, metavar="N",
                       help="read and simulate the runs in parallel on a local Dask cluster of "
                            "N worker processes (needs: pip install lidarjax[dask])")
    group.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="use an existing Dask cluster, e.g. tcp://10.0.0.5:8786 (the "
                            "workers must see the CFD files at the same paths)")


def _set_x64(flag: bool) -> None:
    jax.config.update("jax_enable_x64", bool(flag))


@contextlib.contextmanager
def dask_client(args):
    """A ``distributed.Client`` for ``--workers`` / ``--scheduler`` (None without them), with
    the command's float precision (``--x64``) set on every worker."""
    if args.workers is None and args.scheduler is None:
        yield None
        return

    distributed = import_optional("distributed", "dask", "--workers / --scheduler")
    if args.workers is not None:
        if args.workers < 1:
            raise ValueError(f"--workers must be at least 1, got {args.workers}")
        # No dashboard, and the scheduler's HTTP server on a free port: Dask's default 8787 is
        # taken by any other cluster on the machine (and its "port in use" warning is an error
        # under a strict warning filter).
        cluster = distributed.LocalCluster(n_workers=args.workers, threads_per_worker=1,
                                           processes=True, dashboard_address=None,
                                           scheduler_kwargs={"dashboard_address": ":0"})
    else:
        cluster = None
    try:
        client = distributed.Client(cluster if cluster is not None else args.scheduler)
    except OSError as err:
        if cluster is not None:
            cluster.close()
        raise ValueError(f"cannot reach the Dask scheduler {args.scheduler}: {err}") from None
    try:
        client.run(_set_x64, bool(getattr(args, "x64", True)))
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


class _RegionLoader:
    """``beta -> GridField``: `load` of that beta's file, reading only `region` where the
    reader supports it, exact at the points a run prepares (``exact_at``) where it supports
    that (a plain class so Dask can ship it)."""

    def __init__(self, load, paths, region):
        self.load, self.paths, self.region = load, dict(paths), region
        params = inspect.signature(load).parameters
        self.takes_region = "region" in params
        self.takes_exact = "exact_at" in params

    def __call__(self, beta, exact_at=None):
        """The run of `beta`; with `exact_at` (points, or a function of the resampled grid
        returning them) a mesh is made exact there (`lidarjax.io.load_field`)."""
        kw = {"region": self.region} if self.takes_region else {}
        if exact_at is not None and self.takes_exact:
            kw["exact_at"] = exact_at
        return self.load(self.paths[beta], **kw)


def region_loader(load, paths, region):
    """A picklable loader of the run of each beta restricted to `region` ``(lo, hi)``."""
    return _RegionLoader(load, paths, region)
