"""`jaxskin edit`: the browser editor (`jaxskin.editor`) served on a local port until a
signal stops it."""

from __future__ import annotations

import ipaddress
import socket
import sys

from ..io import InputError
from ._options import number, overrides
from ._process import (
    SIGNAL_ERRORS,
    Run,
    exit_now,
    holding_signals,
    pending_signal,
    raise_received,
    signals_received,
)
from ._terminal import warn

__all__ = ["LOCAL", "add_parser", "run"]

LOCAL = ("127.0.0.1", "localhost", "::1")


def add_parser(sub) -> None:
    """The `jaxskin edit` subcommand and its options."""
    e = sub.add_parser(
        "edit",
        help="edit a scene interactively in the browser (sliders, field edits, painting)",
        description="Start a local web server with an editor for SCENE (default: hand): the "
        "rendered view, every scene value as a slider, direction-field edits picked on the "
        "mesh, cosmetic layers painted on the face; Save writes DIR/<name>.toml (and painted "
        "maps as 16-bit PNGs) that jaxskin render reproduces. Needs pip install "
        "'jaxskin[edit]'. Files the page opens must lie in the scene's folder or DIR.",
    )
    e.add_argument("scene", nargs="?", metavar="SCENE", help="built-in name or TOML file")
    e.add_argument("-o", "--output", default=".", metavar="DIR",
                   help="folder Save writes to (default: the current folder)")
    e.add_argument("--port", type=number(int, 0, 65535), default=0,
                   help="port to serve on (default 0: a free one)")
    e.add_argument("--host", default="127.0.0.1",
                   help="address to serve on (default 127.0.0.1: this machine only; others "
                   "are warned about)")
    e.add_argument("--no-browser", action="store_true", help="do not open a browser")
    overrides(e, "start with a scene value changed, as jaxskin render -D (repeatable)")


def run(args, record: Run) -> int:
    """Check the options and the scene, bind the port, then serve until a signal."""
    try:
        import aiohttp  # noqa: F401
    except ImportError:
        raise InputError("jaxskin edit needs aiohttp: pip install 'jaxskin[edit]'") from None
    from ..editor import make_app

    local = _is_local(args.host)
    record.stage = "loading the scene"
    session = _open_session(args)
    # Bound before the address is printed or a browser opened: a port in use is an error
    # before either, not a browser opened on whatever else listens there.
    sock = _bind(args.host, args.port)
    port = sock.getsockname()[1]
    host = args.host
    url = f"http://{'[' + host + ']' if ':' in host else host}:{port}/"
    record.outputs.append(session)  # what Save and uploads write, for the last line
    record.stage = "serving"
    print(f"jaxskin edit: {session.source} at {url} (Ctrl-C to stop); Save writes to "
          f"{session.output}", flush=True)
    if not args.no_browser:
        import webbrowser

        webbrowser.open(url)
    app = make_app(session, log=lambda line: print(line, file=sys.stderr), local=local)
    _serve(app, sock, record)
    # run_app returns quietly on the KeyboardInterrupt that stopped it (exit 0 for Ctrl-C,
    # where the command line documents 130): the signal is raised again for `main`.
    raise_received()
    return 0


def _is_local(host: str) -> bool:
    """Whether `host` is this machine only; a warning when it is not."""
    local = host in LOCAL
    if not local:
        try:
            local = ipaddress.ip_address(host).is_loopback
        except ValueError:
            local = False
        if not local:
            warn(f"serving on {host}: anyone who can reach this address can read and write "
                 "scenes in the editor's folders; the default 127.0.0.1 is reachable from "
                 "this machine only")
    return local


def _open_session(args):
    """The editor's session on `args.scene` with the `-D` values, the output folder checked
    as `render` checks it (before the server starts: Save names its own files, so
    `-o ed/x.toml` is a slip); `InputError` as the command line says it."""
    from ..editor import EditorError, Session
    from ..outputs import check_folder

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
    except EditorError as e:  # a scene's own error names its file and key already: once
        named = e.key is not None and f"key '{e.key}'" not in e.message
        raise InputError(e.message, key=e.key if named else None) from None
    if refused:
        raise InputError(refused[0]["error"], "-D", key=refused[0]["key"])
    return session


def _bind(host: str, port: int) -> socket.socket:
    """A listening socket on `host:port`, or `InputError`."""
    try:
        family = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM)[0][0]
        return socket.create_server((host, port), family=family)
    except OSError as e:
        raise InputError(f"cannot serve on {host}:{port} ({e.strerror or e})") from None


def _serve(app, sock, record: Run) -> None:
    """Run the server until a signal. Signals are held while the event loop is made, runs
    and closes (`holding_signals`: one raised inside asyncio's own code can leave a
    half-made loop); a held one stops the server within 0.2 s. A render still running in
    its worker thread, which no signal stops, is waited for; a second signal ends the
    process at once (`exit_now`)."""
    import asyncio

    from aiohttp import web

    from ..editor import WATCH, WORK

    async def watch(app):
        """The poll task raises KeyboardInterrupt whatever the signal, as asyncio lets only
        that (and SystemExit) out of the event loop; `raise_received` afterwards raises the
        signal's own exception."""
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
    if signals_received() and work.running:
        if signals_received() > 1:  # Ctrl-C twice: not waiting for the render
            exit_now(record)
        try:  # the line inside: a second signal while it prints also ends it at once
            print("jaxskin: stopping once the render in progress ends; Ctrl-C again stops "
                  "at once", file=sys.stderr, flush=True)
            work.pool.shutdown(wait=True)
        except tuple(SIGNAL_ERRORS.values()):
            exit_now(record)
