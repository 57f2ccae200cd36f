"""The command line both page generators share: write the page, or with ``--check`` exit 1
when the committed page differs from what the generator writes now."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path


def write_or_check(page: Path, render: Callable[[], str], argv: list[str] | None) -> int:
    """Write ``render()`` to `page`; with ``argv == ["--check", ...]`` only compare (0: same)."""
    text = render()
    if argv and argv[0] == "--check":
        return 0 if page.exists() and page.read_text() == text else 1
    page.write_text(text)
    return 0
