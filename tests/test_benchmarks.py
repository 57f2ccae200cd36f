"""The benchmark scripts share one timer and one machine record (`benchmarks/_common.py`), so
every results file says in the same words which backend, device and versions it measured."""

from __future__ import annotations

import ast
import sys

from .helpers import REPO

BENCH = REPO / "benchmarks"


def _scripts():
    return sorted(p for p in BENCH.glob("*.py") if not p.name.startswith("_"))


def test_every_benchmark_that_writes_results_records_the_machine_once():
    missing, own = [], []
    for path in _scripts():
        tree = ast.parse(path.read_text())
        calls = {n.func.id for n in ast.walk(tree)
                 if isinstance(n, ast.Call) and isinstance(n.func, ast.Name)}
        text = path.read_text()
        writes = "json.dump" in text
        if writes and "machine" not in calls:
            missing.append(path.name)
        if "platform.platform()" in text or "os.cpu_count()" in text and "machine" not in calls:
            own.append(path.name)
    assert not missing, f"write results without _common.machine(): {missing}"
    assert not own, f"record the machine their own way: {own}"


def test_machine_record_names_backend_device_and_versions(monkeypatch):
    monkeypatch.syspath_prepend(str(BENCH))
    sys.modules.pop("_common", None)
    import _common

    m = _common.machine()
    for key in ("backend", "device", "cpus", "cpus_usable", "platform", "python", "jax", "numpy"):
        assert key in m
    assert m["backend"] == "cpu" and m["cpus"] >= 1
    line = _common.machine_line(m)
    assert "CPU" in line and m["jax"] in line
    gpu = dict(m, backend="gpu", device="NVIDIA H100 80GB HBM3")
    assert _common.machine_line(gpu).startswith("NVIDIA H100 80GB HBM3 (gpu)")
    t = _common.median_time(lambda: None, 3)
    assert 0 <= t < 0.1
