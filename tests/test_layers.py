"""The package's architecture, checked from its imports: one-way layers, no two modules that
import each other, every internal import at module top, and a flat public API that the README
and docs use.

Layers, lowest first (each may import only itself and the ones before it):

0. shared helpers: ``lidarjax._util``, ``lidarjax._precision``, ``lidarjax._deprecated``;
1. the core (every other module at the package root except ``plots``, ``lidarjax.scanning`` and
   ``lidarjax.control``);
1.5. ``lidarjax.design`` (optimisation through the core: it imports the core, the core never
   imports it);
2. ``lidarjax.scenes``;
3. ``lidarjax.io``;
4. ``lidarjax.plots``;
5. ``lidarjax.workflows``;
6. ``lidarjax.cli``.

The package's ``__init__`` files are facades (re-exports) and stand outside the layers.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

import pytest

import lidarjax as lj

PACKAGE = Path(lj.__file__).resolve().parent
REPO = PACKAGE.parent

HELPERS = {"lidarjax._util", "lidarjax._precision", "lidarjax._deprecated", "lidarjax._backend"}
#: Optional extras that a function may import where it needs them (heavy or absent).
OPTIONAL = {"matplotlib", "xarray", "dask", "distributed", "floris", "meshio", "numba", "hipersim",
            "tqdm", "pandas", "h5netcdf", "h5py", "foamlib", "netCDF4"}


def layer(module: str) -> float:
    if module in HELPERS:
        return 0
    parts = module.split(".")
    if len(parts) >= 2 and parts[1] == "design":  # above the core it optimises through
        return 1.5
    if len(parts) == 2 and parts[1] not in ("scenes", "io", "plots", "workflows", "cli"):
        return 1
    if parts[1] in ("scanning", "control"):  # core subpackages (scanning lidars, lidar-assisted control)
        return 1
    return {"scenes": 2, "io": 3, "plots": 4, "workflows": 5, "cli": 6}[parts[1]]


def _modules():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        parts = list(rel.parts)
        is_init = parts[-1] == "__init__"
        if is_init:
            parts = parts[:-1]
        yield ".".join(parts), path, is_init


def _resolve(node: ast.ImportFrom, module: str, is_init: bool) -> str:
    if not node.level:
        return node.module or ""
    base = module.split(".") if is_init else module.split(".")[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _known(name: str) -> str | None:
    """The lidarjax module `name` refers to (a module itself, else its package)."""
    while name:
        rel = Path(*name.split("."))
        if (REPO / rel).with_suffix(".py").is_file() or (REPO / rel / "__init__.py").is_file():
            return name
        name = name.rpartition(".")[0]
    return None


class _ImportLister(ast.NodeVisitor):
    """(importer, is a package's __init__, imported module, line, inside a function) for every
    import of one module, in one walk that tracks the enclosing function."""

    def __init__(self, module: str, is_init: bool):
        self.module, self.is_init, self.depth, self.found = module, is_init, 0, []

    def _function(self, node):
        self.depth += 1
        self.generic_visit(node)
        self.depth -= 1

    visit_FunctionDef = visit_AsyncFunctionDef = _function

    def _add(self, node, targets):
        self.found += [(self.module, self.is_init, t, node.lineno, self.depth > 0) for t in targets]

    def visit_Import(self, node):
        self._add(node, [a.name for a in node.names])

    def visit_ImportFrom(self, node):
        base = _resolve(node, self.module, self.is_init)
        self._add(node, [f"{base}.{a.name}" for a in node.names] if base.startswith("lidarjax")
                  else [base])


@functools.cache
def imports():
    """(importer, is an __init__, imported module, line, inside a function) for every import in
    lidarjax; parsed once, when the first test here needs it (not at collection)."""
    out = []
    for module, path, is_init in _modules():
        lister = _ImportLister(module, is_init)
        lister.visit(ast.parse(path.read_text()))
        out += lister.found
    return out


def test_internal_imports_all_at_module_top():
    inner = [f"{m}:{line} imports {t}" for m, _, t, line, f in imports()
             if f and t.split(".")[0] == "lidarjax"]
    assert not inner, "imports inside functions hide the dependency direction:\n" + "\n".join(inner)


# Core modules slow to import, imported by the one function that needs them: scipy.signal (with
# the scipy.stats it imports) was 1.1 s of `import lidarjax`'s 5.2 s, for `welch_coherence` alone.
SLOW_TO_IMPORT = {"scipy.signal"}


def test_external_imports_in_functions_only_for_optional_extras():
    inner = [f"{m}:{line} imports {t}" for m, _, t, line, f in imports()
             if f and t.split(".")[0] != "lidarjax" and t.split(".")[0] not in OPTIONAL
             and t not in SLOW_TO_IMPORT]
    assert not inner, "\n".join(inner)


def test_import_lidarjax_leaves_slow_modules_unimported():
    """`import lidarjax` (every CLI command's start) does not import what SLOW_TO_IMPORT lets
    one function import itself."""
    import subprocess
    import sys

    code = f"import sys, lidarjax; print(sorted(m for m in {sorted(SLOW_TO_IMPORT)!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout


def test_layers_import_only_downwards():
    bad = []
    for m, is_init, t, line, _ in imports():
        if is_init or not t.startswith("lidarjax"):
            continue
        target = _known(t)
        if target is None or target == "lidarjax" or target.count(".") == 1 and (
                REPO / "lidarjax" / target.split(".")[1] / "__init__.py").is_file():
            # a subpackage's facade: judge by the subpackage
            target = target if target != "lidarjax" else None
        if target is None:
            continue
        if layer(target) > layer(m):
            bad.append(f"{m} (layer {layer(m)}) imports {target} (layer {layer(target)}), line {line}")
    assert not bad, "\n".join(bad)


def test_core_never_imports_io_workflows_cli_or_plots():
    bad = [f"{m} imports {t}" for m, is_init, t, _, _ in imports()
           if not is_init and layer(m) <= 1 and re.match(r"lidarjax\.(io|workflows|cli|plots)\b", t)]
    assert not bad, "\n".join(bad)


def test_no_two_modules_import_each_other():
    edges = {}
    for m, is_init, t, _, _ in imports():
        target = _known(t) if t.startswith("lidarjax") else None
        if target and target != m and not is_init:
            edges.setdefault(m, set()).add(target)
    pairs = sorted({tuple(sorted((a, b))) for a, bs in edges.items() for b in bs
                    if a in edges.get(b, ())})
    assert not pairs, pairs


def test_the_layering_rule_is_not_vacuous():
    """The walker sees the imports it judges (a refactor that hid them would pass silently)."""
    seen = {(m, _known(t)) for m, _, t, _, _ in imports() if t.startswith("lidarjax")}
    assert ("lidarjax.forward", "lidarjax.field") in seen
    assert ("lidarjax.workflows.records", "lidarjax.inverse") in seen
    assert ("lidarjax.io.tables", "lidarjax.response") in seen
    assert layer("lidarjax.forward") == 1 and layer("lidarjax.io.sta") == 3
    assert layer("lidarjax.cli.farm") == 6
    assert layer("lidarjax.design.placement") == 1.5 and layer("lidarjax.design") == 1.5
    assert ("lidarjax.design.placement", "lidarjax.forward") in seen


# -- the public API ---------------------------------------------------------------------------
NAMESPACES = {"lidarjax", "lidarjax.scenes", "lidarjax.io", "lidarjax.plots", "lidarjax.control"}


def _docs_code():
    for path in [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]:
        text = path.read_text()
        for block in re.findall(r"```python\n(.*?)```", text, re.S):
            yield path.name, block


def _walk(dotted: str):
    """Resolve ``lj.a.b.c`` attribute by attribute: the modules passed on the way, the object."""
    import types

    obj, modules = lj, []
    for p in dotted.strip(".").split("."):
        if not hasattr(obj, p):
            return modules, None  # an attribute of a result (sim.los): not the API
        obj = getattr(obj, p)
        if isinstance(obj, types.ModuleType):
            modules.append(obj.__name__)
    return modules, obj


def test_docs_import_and_use_only_public_names():
    """README and docs reach names only as ``lidarjax.<name>`` or through the namespaces
    (``scenes``, ``io``, ``plots``), never through an implementation module, and nothing they
    use is a deprecated alias."""
    import warnings

    bad = []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for name, block in _docs_code():
            for line in block.splitlines():
                m = re.match(r"\s*from (lidarjax[\w.]*) import (.+)", line)
                if m and m.group(1) not in NAMESPACES:
                    bad.append(f"{name}: {line.strip()}")
                elif m:
                    for item in m.group(2).split("#")[0].split(","):
                        attr = item.split(" as ")[0].strip(" ()")
                        try:
                            _walk(f"{m.group(1)[len('lidarjax'):]}.{attr}")
                        except DeprecationWarning as err:
                            bad.append(f"{name}: {line.strip()} ({err})")
                for deep in re.findall(r"\b(?:lj|lidarjax)((?:\.\w+)+)", line):
                    try:
                        modules, _ = _walk(deep)
                    except DeprecationWarning as err:
                        bad.append(f"{name}: {line.strip()} ({err})")
                        continue
                    hidden = [mod for mod in modules if mod not in NAMESPACES]
                    if hidden:
                        bad.append(f"{name}: {line.strip()} (through {hidden[0]})")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize("ns", sorted(NAMESPACES - {"lidarjax.plots"}))
def test_namespaces_export_what_their_modules_promise(ns):
    import importlib

    mod = importlib.import_module(ns)
    names = [n for n in dir(mod) if not n.startswith("_")]
    assert names


def test_deprecated_aliases_warn_once_and_work():
    with pytest.warns(DeprecationWarning, match="simulate_rotations"):
        assert lj.simulate_sectors is lj.simulate_rotations
    with pytest.warns(DeprecationWarning, match="lidarjax.angles.heading"):
        assert lj.scenes.heading is lj.heading
    with pytest.warns(DeprecationWarning, match="lidarjax.flags.RecordFlag"):
        assert lj.io.RecordFlag is lj.RecordFlag
    with pytest.warns(DeprecationWarning, match="lidarjax.workflows.seed_tables"):
        from lidarjax.workflow import build_table
    assert build_table is lj.build_table
    with pytest.warns(DeprecationWarning, match="lidarjax.turbulence"):
        import lidarjax.turbulence_box as tb
    assert tb.fft_mann_box is lj.fft_mann_box
    with pytest.raises(AttributeError):
        lj.no_such_name  # noqa: B018
