"""The documentation is tested: the site builds with ``mkdocs build --strict`` (a broken link
or a missing API reference fails), every public name has an entry in the built site's
``objects.inv``, the generated pages (command line, benchmarks) equal what their scripts
write now, ``__all__`` lists exactly what each package exports, ``lidarjax --version`` is
the package's version, and every Python code block of ``docs/`` runs.

A code block that must not run is preceded by a line ``<!-- not run: REASON -->``; the
reason is required.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import re
import subprocess
import sys
import types
import zlib
from pathlib import Path

import pytest

import lidarjax
import lidarjax.design
import lidarjax.io
import lidarjax.scanning
import lidarjax.scenes

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
sys.path.insert(0, str(ROOT / "tools" / "docs"))

#: the package and its subpackages with an ``__all__``, and the namespaces lidarjax re-exports
PACKAGES = {"lidarjax": lidarjax, "lidarjax.io": lidarjax.io, "lidarjax.scenes": lidarjax.scenes,
            "lidarjax.scanning": lidarjax.scanning, "lidarjax.design": lidarjax.design}
NAMESPACES = {"io", "plots", "scenes"}


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


def _python_blocks(text: str):
    """``(line, code, reason)`` of each python fence; reason is None when it runs."""
    lines = text.splitlines()
    out = []
    i = 0
    while i < len(lines):
        if lines[i].strip() == "```python":
            start = i
            j = i + 1
            while lines[j].strip() != "```":
                j += 1
            prev = next((lines[k] for k in range(start - 1, -1, -1) if lines[k].strip()), "")
            m = re.match(r"\s*<!-- not run: (.+?) -->", prev)
            out.append((start + 1, "\n".join(lines[start + 1:j]), m.group(1) if m else None))
            i = j
        i += 1
    return out


GENERATED = {"cli.md", "benchmarks.md"}
PAGES = sorted(p for p in DOCS.rglob("*.md") if p.name not in GENERATED and "data" not in p.parts)


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(DOCS)))
def test_code_blocks_run(page, tmp_path, monkeypatch):
    """Each page's blocks run in order in one namespace (a later block uses an earlier
    block's names), in a temporary working folder that sees the clone's ``docs/`` and
    ``tests/`` (the pages read the committed files as a reader does from a clone's root)."""
    blocks = _python_blocks(page.read_text())
    if not blocks:
        return
    for name in ("docs", "tests"):
        (tmp_path / name).symlink_to(ROOT / name)
    monkeypatch.chdir(tmp_path)
    namespace: dict = {"__name__": "__docs__"}
    for line, code, reason in blocks:
        if reason is not None:
            assert len(reason) > 10, f"{page.name}:{line}: say why the block does not run"
            continue
        exec(compile(code, f"{page.relative_to(ROOT)}:{line}", "exec"), namespace)  # noqa: S102
