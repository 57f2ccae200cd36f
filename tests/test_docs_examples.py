"""Every Python code block of ``docs/`` runs, with CPU-sized inputs (the README's example
runs in tests/test_readme.py). A block that must not run is preceded by a line
``<!-- not run: REASON -->``; the reason is required. Kept apart from tests/test_docs.py so
that the two spread over the suite's workers.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


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
