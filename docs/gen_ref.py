"""Generate the reference pages from the code (run by mkdocs-gen-files at every build):
the API pages, the scene format and the command line (`docs/_ext/reference.py` makes
them); the benchmarks' plots are copied in as `benchmarks/*.png`, as they are now. A
public name without a docstring, or a scene key without a description, is logged as a
warning, which fails `mkdocs build --strict`."""

from __future__ import annotations

import logging
import sys
from pathlib import Path

import mkdocs_gen_files

sys.path.insert(0, str(Path(__file__).resolve().parent / "_ext"))
import reference  # noqa: E402

log = logging.getLogger("mkdocs.plugins.jaxskin_reference")

pages, api_nav = reference.api_pages()
scene_md, undescribed = reference.scene_page()
pages["reference/scene.md"] = scene_md  # kept in the repository too (reference.KEPT)
pages["reference/cli.md"] = reference.cli_page()
bench = reference.ROOT / "benchmarks"
for png in sorted(bench.rglob("*.png")):  # the benchmarks' plots, as they are now
    with mkdocs_gen_files.open(f"benchmarks/{png.relative_to(bench).as_posix()}", "wb") as f:
        f.write(png.read_bytes())
for path, text in pages.items():
    with mkdocs_gen_files.open(path, "w") as f:
        f.write(text)
for key in undescribed:
    log.warning(f"scene key '{key}' has no description: give it a comment in the TOML "
                "example of jaxskin/scene/__init__.py's docstring")
for name in reference.missing_docstrings():
    log.warning(f"public name without a docstring: {name}")
for section in mkdocs_gen_files.config.nav:
    if isinstance(section, dict) and "Reference" in section:
        section["Reference"] = [e for e in section["Reference"]
                                if not (isinstance(e, dict) and "API" in e)] + api_nav
