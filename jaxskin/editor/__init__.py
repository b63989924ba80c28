"""`jaxskin edit`: an interactive editor in the browser.

A local web application over the same renderer as `jaxskin render`: sliders for every
scene value, direction-field edits picked on the mesh (Bando 2001 §3.1), cosmetic layers
painted on the face (Huang et al. 2013 §3), the state in the page's URL, Save as a scene
file that `jaxskin render` reproduces byte for byte. The command (`jaxskin.cli`) serves it,
`jaxskin.scene` writes the scenes, `static/` is the page (plain HTML, CSS and JavaScript: no
build step, nothing fetched from the network).

Its private files:

- `_session.py`: the `Session`: its scene, opened and confined to its folders, and what
  the page shows of it;
- `_changes.py`: scene keys set from the page, checked, undone and redone;
- `_render.py`: the view rendered as `jaxskin render` renders it, and previews;
- `_paint.py`: a vertex picked on the view, the fields' arrows, brush strokes;
- `_brush.py`: the soft brush's dabs in texture space;
- `_save.py`: Save and uploads into the output folder, the source's comments kept;
- `_document.py`: the scene's TOML document changed by flat keys, `EditorError`;
- `_server.py`: the HTTP API (aiohttp) and its worker thread.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from ._document import EditorError as EditorError
    from ._document import relocate as relocate
    from ._save import keep_comments as keep_comments
    from ._server import MAX_BODY as MAX_BODY
    from ._server import WATCH as WATCH
    from ._server import WORK as WORK
    from ._server import make_app as make_app
    from ._session import Session as Session

__all__ = ["MAX_BODY", "WATCH", "WORK", "EditorError", "Session", "keep_comments", "make_app",
           "relocate"]

# Each re-exported name is imported when first asked for (`__getattr__`): importing the
# package must not import aiohttp before `jaxskin edit` checks it is there (its message says
# how to install it), nor NumPy and the renderer before they are needed.
_LAZY = {"EditorError": "_document", "relocate": "_document", "keep_comments": "_save",
         "MAX_BODY": "_server", "WATCH": "_server", "WORK": "_server", "make_app": "_server",
         "Session": "_session"}


def __getattr__(name: str):
    """A re-exported name, its private file imported on first use (`_LAZY`)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)
