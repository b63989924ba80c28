"""`jaxskin edit`: an interactive editor in the browser.

A local web application over the same renderer as `jaxskin render`: sliders for every
scene value, direction-field edits picked on the mesh (Bando 2001 §3.1), cosmetic layers
painted on the face (Huang et al. 2013 §3), the state in the page's URL, Save as a scene
file that `jaxskin render` reproduces byte for byte. `jaxskin.toml_writer` writes scenes,
`static/` is the page (plain HTML, CSS and JavaScript: no build step, nothing fetched from
the network).

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
import ipaddress
import socket
import sys
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

__all__ = ["MAX_BODY", "WATCH", "WORK", "EditorError", "Session", "command", "keep_comments",
           "make_app", "relocate"]

# Each re-exported name is imported when first asked for (`__getattr__`): importing the
# package for `jaxskin edit` must not import aiohttp before `command` checks it is there
# (its message says how to install it), nor NumPy and the renderer before they are needed.
_LAZY = {"EditorError": "_document", "relocate": "_document", "keep_comments": "_save",
         "MAX_BODY": "_server", "WATCH": "_server", "WORK": "_server", "make_app": "_server",
         "Session": "_session"}

LOCAL = ("127.0.0.1", "localhost", "::1")


def __getattr__(name: str):
    """A re-exported name, its private file imported on first use (`_LAZY`)."""
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return getattr(importlib.import_module(f".{module}", __name__), name)


def command(args, run) -> int:
    """The body of `jaxskin edit` (see `jaxskin edit --help`)."""
    from ..io import InputError

    try:
        import aiohttp  # noqa: F401
    except ImportError:
        raise InputError("jaxskin edit needs aiohttp: pip install 'jaxskin[edit]'") from None
    from aiohttp import web

    from . import WATCH, WORK, EditorError, Session, make_app

    host = args.host
    local = host in LOCAL
    if not local:
        try:
            local = ipaddress.ip_address(host).is_loopback
        except ValueError:
            local = False
        if not local:
            print(f"jaxskin: warning: serving on {host}: anyone who can reach this address "
                  "can read and write scenes in the editor's folders; the default 127.0.0.1 "
                  "is reachable from this machine only", file=sys.stderr, flush=True)
    run.stage = "loading the scene"
    from ..outputs import check_folder

    # as render checks it, before the server starts: `-o afile` served, and Save failed
    # with an internal error (a trial); Save names its files, so `-o ed/x.toml` is a slip
    check_folder(args.output, "-o")
    try:
        session = Session(args.scene or "hand", args.output)
        pairs = []
        for item in args.overrides:
            key, sep, value = (t.strip() for t in item.partition("="))
            if not sep:
                raise InputError(f"expected -D key=value, got {item!r}")
            pairs.append([key, value])
        refused = session.open(session.source, pairs)
    except EditorError as e:  # a scene's own error names its file and key already (they
        named = e.key is not None and f"key '{e.key}'" not in e.message  # came twice: a trial)
        raise InputError(e.message, key=e.key if named else None) from None
    if refused:
        raise InputError(refused[0]["error"], "-D", key=refused[0]["key"])
    # Bound before the address is printed or a browser opened: a port in use is an error
    # before either (the browser once opened on whatever else listened there).
    try:
        family = socket.getaddrinfo(host, args.port, type=socket.SOCK_STREAM)[0][0]
        sock = socket.create_server((host, args.port), family=family)
    except OSError as e:
        raise InputError(f"cannot serve on {host}:{args.port} ({e.strerror or e})") from None
    port = sock.getsockname()[1]
    url = f"http://{'[' + host + ']' if ':' in host else host}:{port}/"
    run.outputs.append(session)  # what Save and uploads write, for the last line
    run.stage = "serving"
    print(f"jaxskin edit: {session.source} at {url} (Ctrl-C to stop); Save writes to "
          f"{session.output}", flush=True)
    if not args.no_browser:
        import webbrowser

        webbrowser.open(url)
    from ..cli import (
        _SIGNAL_ERRORS,
        exit_now,
        holding_signals,
        pending_signal,
        raise_received,
        signals_received,
    )

    app = make_app(session, log=lambda line: print(line, file=sys.stderr), local=local)

    async def watch(app):
        """Signals are held while the loop is made, runs and closes (`holding_signals`:
        raised inside asyncio's own code, one left a half-made loop); a held one stops the
        server within 0.2 s. The task raises KeyboardInterrupt whatever the signal, as
        asyncio lets only that (and SystemExit) out of the event loop; `raise_received`
        below raises the signal's own exception."""
        import asyncio

        async def poll():
            while True:
                await asyncio.sleep(0.2)
                if pending_signal():
                    raise KeyboardInterrupt

        app[WATCH] = asyncio.get_running_loop().create_task(poll())

    app.on_startup.append(watch)
    with holding_signals():
        web.run_app(app, sock=sock, print=None, handle_signals=False)
    task = app.get(WATCH)
    if task is not None and task.done() and not task.cancelled():
        task.exception()  # retrieved: no "Task exception was never retrieved" traceback
    work = app[WORK]
    if signals_received() and work.running:  # a render in its thread, which no signal stops
        if signals_received() > 1:  # Ctrl-C twice: not waiting (it was 8 s at 1024², and a
            exit_now(run)  # third one raised inside the interpreter's wait; a review)
        try:  # the line inside: a second signal while it prints also ends it at once
            print("jaxskin: stopping once the render in progress ends; Ctrl-C again stops "
                  "at once", file=sys.stderr, flush=True)
            work.pool.shutdown(wait=True)
        except tuple(_SIGNAL_ERRORS.values()):
            exit_now(run)
    # run_app returns quietly on the KeyboardInterrupt that stopped it (exit 0 for Ctrl-C,
    # where the command line documents 130): the signal is raised again for `cli.main`.
    raise_received()
    return 0
