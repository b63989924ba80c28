"""An MkDocs hook: log how long each page takes to render (its executed examples included),
so a slow example shows up in the build log (`mkdocs build` prints INFO lines)."""

import logging
import time

log = logging.getLogger("mkdocs.hooks.timing")
_started: dict[str, float] = {}


def on_page_markdown(markdown, page, **kwargs):
    _started[page.file.src_uri] = time.perf_counter()
    return markdown


def on_page_content(html, page, **kwargs):
    seconds = time.perf_counter() - _started.pop(page.file.src_uri, time.perf_counter())
    if seconds > 0.5:
        log.info(f"{page.file.src_uri}: {seconds:.1f} s")
    return html
