"""Helpers for the tutorials' executed code blocks (markdown-exec), imported by their hidden
set-up blocks: each page works in a fresh temporary folder, runs its commands through the
same `jaxskin.cli.main` the `jaxskin` script calls, and embeds the images it makes (as data
URIs, so the built site holds no file that could go stale).

markdown-exec collects what a block's own `print` writes, so these return Markdown for
the block to print: `print(run("jaxskin ..."))`, `print(show("x.png"))`."""

from __future__ import annotations

import base64
import contextlib
import html
import io
import os
import re
import shlex
import shutil
import tempfile
from pathlib import Path

import numpy as np

_START: list[tuple[str, str]] = []  # (the folder the build ran in, the page's temporary one)


def start() -> Path:
    """Move into a new empty temporary folder for this page (`finish` leaves and deletes it)."""
    os.environ.setdefault("JAXSKIN_NO_COMPILE_CACHE", "1")
    folder = tempfile.mkdtemp(prefix="jaxskin-docs-")
    _START.append((os.getcwd(), folder))
    os.chdir(folder)
    return Path(folder)


def finish() -> None:
    """Back to the build's folder; the page's temporary folder is deleted."""
    cwd, folder = _START.pop()
    os.chdir(cwd)
    shutil.rmtree(folder, ignore_errors=True)


def _clean(text: str) -> str:
    """Terminal output as a reader would see it: progress bars (tqdm redraws with `\\r`)
    reduced to their last state, trailing spaces dropped."""
    lines = []
    for line in text.splitlines():
        line = line.rsplit("\r", 1)[-1].rstrip()
        if line:
            lines.append(line)
    return "\n".join(lines)


def run(command: str, expect: int = 0) -> str:
    """Run a `jaxskin ...` command line in-process and print it with its output as a console
    block; a different exit code than `expect` fails the build."""
    from jaxskin.cli import main

    words = shlex.split(command)
    assert words[0] == "jaxskin", command
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        code = main(words[1:])
    text = _clean(out.getvalue() + err.getvalue())
    if code != expect:
        raise RuntimeError(f"`{command}` exited {code}, expected {expect}:\n{text}")
    return f"```console\n$ {command}\n{text}\n```\n"


def _png(image) -> bytes:
    if isinstance(image, (str, Path)):
        return Path(image).read_bytes()
    from jaxskin.maps import png_bytes

    a = np.asarray(image)
    if a.dtype != np.uint8:
        a = np.round(np.clip(a.astype(np.float64), 0.0, 1.0) * 255).astype(np.uint8)
    return png_bytes(a)


def show(*images, caption: str = "", width: int = 0) -> str:
    """Embed PNG files or images side by side, with a caption: float arrays are display
    values in [0, 1] (what `render.render` returns; clipped), uint8 arrays are taken as
    they are."""
    style = f' style="width:{width}px;image-rendering:pixelated"' if width else ""
    tags = "".join(f'<img alt="{html.escape(caption)}" src="data:image/png;base64,'
                   f'{base64.b64encode(_png(im)).decode()}"{style}>' for im in images)
    cap = f"<figcaption>{html.escape(caption)}</figcaption>" if caption else ""
    row = ('<div style="display:flex;flex-wrap:wrap;gap:6px;justify-content:center">'
           f"{tags}</div>")
    return f"<figure>{row}{cap}</figure>\n"


def head(path, lines: int = 8) -> str:
    """Print the first `lines` lines of a text file as a code block."""
    text = Path(path).read_text().splitlines()[:lines]
    return "```text\n" + "\n".join(text) + "\n```\n"


def table(rows, header) -> str:
    """A Markdown table."""
    out = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out) + "\n"


def slug(text: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


def results(marker: str | None = None, *, images: str, root: str = ".") -> str:
    """`benchmarks/RESULTS.md` as the benchmarks last wrote it (`marker`: only the section
    between `<!-- marker:start -->` and the next `<!-- ...:end -->`), its headings moved down
    a level (to level 3 for a section), its plots linked under `images` (the site holds a
    copy of `benchmarks/*.png`, made by docs/gen_ref.py at each build). markdown-exec
    renders this Markdown itself, so MkDocs does not rewrite these links: `images` is
    relative to the page's URL (`../../benchmarks/` from `explanations/sss/`)."""
    text = (Path(root) / "benchmarks" / "RESULTS.md").read_text()
    if marker is None:
        body = re.sub(r"^(#+) ", r"#\1 ", text.split("\n", 1)[1], flags=re.M)
    else:
        start = text.index(f"<!-- {marker}:start -->")
        end = text.index(":end -->", start)
        body = text[start:end].split("\n", 1)[1].rsplit("\n", 1)[0]
        body = re.sub(r"^#+ ", "### ", body, flags=re.M)
    body = re.sub(r"<!-- [\w-]+:(start|end) -->\n?", "", body)
    return re.sub(r"!\[([^]]*)\]\(([^)/]+\.png)\)", rf"![\1]({images}\2)", body)
