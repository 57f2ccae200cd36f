"""The documentation is tested: the site builds with ``mkdocs build --strict`` (a broken link
or a missing API reference fails), every public name has an entry in the built site's
``objects.inv``, the generated pages (command line, benchmarks) equal what their scripts
write now, ``__all__`` lists exactly what each package exports, and ``lidarjax --version`` is
the package's version. The code blocks of ``docs/`` run in tests/test_docs_examples.py.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import subprocess
import sys
import types
import zlib
from pathlib import Path

import pytest

import lidarjax
import lidarjax.control
import lidarjax.design
import lidarjax.io
import lidarjax.scanning
import lidarjax.scenes

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(ROOT / "tools" / "docs"))

#: the package and its subpackages with an ``__all__``, and the namespaces lidarjax re-exports
PACKAGES = {"lidarjax": lidarjax, "lidarjax.io": lidarjax.io, "lidarjax.scenes": lidarjax.scenes,
            "lidarjax.scanning": lidarjax.scanning, "lidarjax.design": lidarjax.design,
            "lidarjax.control": lidarjax.control}
NAMESPACES = {"io", "plots", "scenes", "control"}


def _exported(module) -> set[str]:
    """The public names a module binds that are not modules (what it re-exports)."""
    return {n for n, v in vars(module).items()
            if not n.startswith("_") and not isinstance(v, types.ModuleType)}


@pytest.mark.parametrize("name", sorted(PACKAGES))
def test_all_lists_exactly_what_the_package_exports(name):
    module = PACKAGES[name]
    names = list(module.__all__)
    assert len(names) == len(set(names)), "duplicates in __all__"
    expected = _exported(module) | (NAMESPACES if module is lidarjax else set())
    assert set(names) == expected, (sorted(expected - set(names)), sorted(set(names) - expected))
    for n in names:
        assert getattr(module, n) is not None


def test_version_has_one_source(capsys):
    from lidarjax.cli import main

    assert lidarjax.__version__ == importlib.metadata.version("lidarjax")
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"lidarjax {lidarjax.__version__}"


@pytest.mark.parametrize("script", ["gen_cli", "gen_benchmarks"])
def test_generated_pages_are_current(script):
    gen = importlib.import_module(script)
    assert gen.PAGE.read_text() == gen.render(), (
        f"{gen.PAGE.relative_to(ROOT)} is out of date: run python tools/docs/{script}.py")


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    """The site built once, strictly, into a temporary folder."""
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1",
               PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    done = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--quiet",
                           "--site-dir", str(out)], cwd=ROOT, env=env, capture_output=True,
                          text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-4000:]
    return out


def test_mkdocs_build_strict(site):
    for page in ("index.html", "getting-started/index.html", "tutorial/index.html",
                 "conventions/index.html", "benchmarks/index.html", "cli/index.html",
                 "api/model/index.html"):
        assert (site / page).is_file(), page
    assert (site / "benchmarks/results/forward.png").is_file()
    assert (site / "javascripts/katex/katex.min.js").is_file()


def _inventory(path: Path) -> set[str]:
    head, _, rest = path.read_bytes().partition(b"zlib.\n")
    assert b"# Sphinx inventory version 2" in head
    return {line.split(" ", 1)[0] for line in zlib.decompress(rest).decode().splitlines()}


def test_every_public_name_is_in_objects_inv(site):
    inv = _inventory(site / "objects.inv")
    missing = []
    for pkg, module in PACKAGES.items():
        for n in module.__all__:
            if module is lidarjax and n in NAMESPACES:
                continue
            here = f"{pkg}.{n}" in inv
            # a subpackage's name documented once, as lidarjax.<name>, when it is that object
            top = n in lidarjax.__all__ and getattr(lidarjax, n) is getattr(module, n) \
                and f"lidarjax.{n}" in inv
            if not (here or top):
                missing.append(f"{pkg}.{n}")
    assert not missing, f"no API entry for {missing}: add a ::: block to a page in docs/api/"
