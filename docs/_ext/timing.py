"""An MkDocs hook: log how long each page takes to render (its executed examples included),
in wall-clock and CPU time, so a slow example shows up in the build log (`mkdocs build`
prints INFO lines); and the whole build's CPU time at the end."""

import logging
import time

log = logging.getLogger("mkdocs.hooks.timing")
_started: dict[str, tuple[float, float]] = {}


def on_page_markdown(markdown, page, **kwargs):
    _started[page.file.src_uri] = (time.perf_counter(), time.process_time())
    return markdown


def on_page_content(html, page, **kwargs):
    wall, cpu = _started.pop(page.file.src_uri, (time.perf_counter(), time.process_time()))
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    if wall > 0.5:
        log.info(f"{page.file.src_uri}: {wall:.1f} s ({cpu:.1f} s CPU)")
    return html


def on_post_build(config, **kwargs):
    log.info(f"CPU time of the build so far: {time.process_time():.1f} s")
