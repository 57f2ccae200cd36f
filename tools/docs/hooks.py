"""mkdocs hooks: the benchmark results' pictures and JSON, which live beside the scripts that
write them (``benchmarks/results/``), are served by the site at the same relative path, so a
page links ``benchmarks/results/forward.png`` without a copy in ``docs/``."""

from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File

ROOT = Path(__file__).resolve().parents[2]
SHARED = ("benchmarks/results",)
SUFFIXES = {".png", ".json"}


def on_files(files, config):
    """Add every ``benchmarks/results/*.png|json`` to the site's files."""
    for folder in SHARED:
        for path in sorted((ROOT / folder).iterdir()):
            if path.suffix in SUFFIXES and files.get_file_from_path(f"{folder}/{path.name}") is None:
                files.append(File(f"{folder}/{path.name}", str(ROOT), config["site_dir"],
                                  config["use_directory_urls"]))
    return files
