"""The editor's HTTP server (aiohttp): one page, a JSON API, rendered views as PNG.

Every request that touches the scene runs on one worker thread, in arrival order, so JAX
sees one caller and the state one writer; the event loop stays free to answer. Renders
are latest-wins per client: a render request that a newer one from the same client
(`client=` in its query) overtook before it started is answered 409 `superseded`, never
rendered. Every error is a JSON object `{"error": ..., "key": ...}` with a 4xx status
(5xx only for a bug), and the server keeps serving.

| method | path | body / query | answer |
|---|---|---|---|
| GET | `/` | | the page |
| GET | `/static/<file>` | | its script and style |
| GET | `/api/state` | | the session (`Session.state`) |
| GET | `/api/files` | | scenes and materials the page may open |
| POST | `/api/open` | `{scene, changes?}` | state, and `refused` changes |
| POST | `/api/apply` | `{changes}` (a link's, without `scene=`) | state, and `refused` |
| POST | `/api/set` | `{changes: {key: value or null}}` | state |
| POST | `/api/undo`, `/api/redo` | | state |
| POST | `/api/pick` | `{x, y}` (image pixels) | the nearest vertex |
| GET | `/api/fields` | `step=` | arrows and edit markers |
| POST | `/api/paint` | `{stroke, layer, points, radius, strength, erase}` | `{dabs}` |
| GET | `/api/render` | `client=`, `preview=1` | `image/png` (a preview: `image/bmp`) |
| POST | `/api/save` | `{name, overwrite?}` | the files written, state |
| POST | `/api/upload` | `name=` and the file's bytes | `{path}` (kept in the output folder) |
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import functools
import importlib.resources
import ipaddress
import json
import threading
import time
from pathlib import Path

from aiohttp import web

from ._document import EditorError
from ._session import Session

__all__ = ["MAX_BODY", "make_app"]

MAX_BODY = 1 << 20  # bytes: the largest request body (a long paint stroke is ~100 kB)
STATIC = ("index.html", "editor.js", "editor.css")
LOG = web.AppKey("log", object)
WORK = web.AppKey("work", object)  # the `_Worker` (the command waits for it when stopped)
WATCH = web.AppKey("signal_watch", object)  # the command's signal poll (an asyncio task)


def _static_dir() -> Path:
    return Path(str(importlib.resources.files("jaxskin.editor") / "static"))


async def _no_content(request):
    return web.Response(status=204)


def _error(status: int, message: str, key=None) -> web.Response:
    return web.json_response({"error": message, "key": key}, status=status)


@web.middleware
async def _errors(request, handler):
    """Every failure as a JSON error; a bug is a 500 with one line, and the server goes on."""
    try:
        return await handler(request)
    except EditorError as e:
        return web.json_response(e.json(), status=e.status)
    except web.HTTPRequestEntityTooLarge as e:
        return _error(413, f"request body too large (at most {MAX_BODY} bytes): {e.text}")
    except web.HTTPException as e:
        if e.status >= 400:
            return _error(e.status, e.reason)
        raise
    except Exception as e:  # noqa: BLE001  (a bug: say what, keep serving)
        request.app[LOG](f"jaxskin edit: internal error: {e.__class__.__name__}: {e}")
        return _error(500, f"internal error ({e.__class__.__name__}: {e})")


def _loopback(host: str | None) -> bool:
    """Whether `host` (a Host header's name, no port) names this machine's loopback."""
    if host is None:
        return False
    if host.lower() == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def _guard(local: bool):
    """Requests only from the editor's own page. Any web page the user opens may send a
    browser's "simple" requests (a POST with a text/plain body, no preflight) to
    127.0.0.1, and one could overwrite the scene the editor started from. So: a request
    whose Origin is not this server's is refused (browsers send Origin with every
    cross-origin POST; curl sends none); served on loopback, a Host that is not a loopback
    name is refused (DNS rebinding: a foreign name resolved to 127.0.0.1, same-origin to
    the browser); a JSON endpoint's body must be declared application/json, which no page
    can send elsewhere without a preflight this server never allows."""
    @web.middleware
    async def guard(request, handler):
        if local and not _loopback(request.url.host):
            return _error(403, f"refused: Host {request.host!r} is not this machine's "
                               "loopback address (open the editor at the address it printed)")
        origin = request.headers.get("Origin")
        if origin is not None and origin != f"{request.scheme}://{request.host}":
            return _error(403, f"refused: a request from another page (Origin {origin!r:.80})")
        if (request.method == "POST" and request.path != "/api/upload"
                and (request.content_length or request.body_exists)
                and request.content_type != "application/json"):
            return _error(415, f"expected Content-Type application/json, got "
                               f"{request.content_type!r}")
        return await handler(request)
    return guard


class _Worker:
    """One thread for everything that touches the session (and JAX)."""

    def __init__(self):
        self.pool = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="jaxskin-edit")
        self.running = 0  # a call in progress (the command waits for it when stopped)

    async def __call__(self, fn, *args, **kwargs):
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self.pool, self._run,
                                          functools.partial(fn, *args, **kwargs))

    def _run(self, call):
        self.running += 1
        try:
            return call()
        finally:
            self.running -= 1


async def _body(request) -> dict:
    if request.content_length is not None and request.content_length > MAX_BODY:
        raise EditorError(f"request body too large (at most {MAX_BODY} bytes)", 413)
    raw = await request.read()
    try:
        body = json.loads(raw or b"{}")
    except (ValueError, UnicodeDecodeError, RecursionError) as e:
        raise EditorError(f"expected a JSON body ({e.__class__.__name__}: {e})"[:300],
                          400) from None
    if not isinstance(body, dict):
        raise EditorError("expected a JSON object", 400)
    return body


def make_app(session: Session, log=print, local: bool = True) -> web.Application:
    """The aiohttp application serving `session`; `local`: served on a loopback address,
    so a request naming another Host is refused (`_guard`)."""
    app = web.Application(middlewares=[_errors, _guard(local)], client_max_size=MAX_BODY)
    app[LOG] = log
    work = _Worker()
    app.add_routes(_Api(session, work).routes())
    app.on_cleanup.append(_close)
    app[WORK] = work
    return app


async def _close(app) -> None:
    """On the server's cleanup: the worker stops, calls not yet started cancelled."""
    app[WORK].pool.shutdown(wait=False, cancel_futures=True)


class _Api:
    """The route handlers: each request's body checked here, the session's work done on
    the worker thread (`work`)."""

    def __init__(self, session: Session, work: _Worker):
        self.session, self.work = session, work
        self.latest: dict[str, int] = {}  # client → its newest render request's number
        self.counter = iter(range(1, 1 << 62))
        self.lock = threading.Lock()
        self.cache: dict = {}  # the last image made: its key, bytes, type and seconds

    def routes(self) -> list:
        """Every route of the API (the table in the module's docstring)."""
        return [
            web.get("/", self.page), web.get("/static/{name}", self.static),
            web.get("/favicon.ico", _no_content),
            web.get("/api/state", self.state), web.get("/api/files", self.files),
            web.post("/api/open", self.open_), web.post("/api/apply", self.apply),
            web.post("/api/set", self.set_),
            web.post("/api/undo", self.undo), web.post("/api/redo", self.redo),
            web.post("/api/pick", self.pick), web.get("/api/fields", self.fields),
            web.post("/api/paint", self.paint), web.get("/api/render", self.render),
            web.post("/api/save", self.save), web.post("/api/upload", self.upload),
        ]

    async def page(self, request):
        """GET `/`: the page."""
        return web.FileResponse(_static_dir() / "index.html",
                                headers={"Cache-Control": "no-store"})

    async def static(self, request):
        """GET `/static/<file>`: the page's script and style (only those)."""
        name = request.match_info["name"]
        if name not in STATIC:
            raise EditorError(f"no such file {name!r}", 404)
        return web.FileResponse(_static_dir() / name, headers={"Cache-Control": "no-store"})

    async def state(self, request):
        """GET `/api/state`: the session (`Session.state`)."""
        return web.json_response(await self.work(self.session.state))

    async def files(self, request):
        """GET `/api/files`: the scenes and materials the page may open."""
        return web.json_response(await self.work(self.session.files))

    async def open_(self, request):
        """POST `/api/open` `{scene, changes?}`: the state, and the changes `refused`."""
        body = await _body(request)
        scene, changes = body.get("scene"), body.get("changes", {})
        if not isinstance(scene, str) or not isinstance(changes, (dict, list)):
            raise EditorError("expected {scene: name or file, changes: {key: value} or "
                              "[[key, TOML value], ...]}", 400)

        def run():
            refused = self.session.open(scene, changes)
            return {**self.session.state(), "refused": refused}
        return web.json_response(await self.work(run))

    async def apply(self, request):
        """POST `/api/apply` `{changes}`: a link's changes applied to the scene open now;
        the state, and the changes `refused`."""
        changes = (await _body(request)).get("changes")
        if not isinstance(changes, (dict, list)):
            raise EditorError("expected {changes: {key: value} or [[key, TOML value], ...]}",
                              400)

        def run():
            refused = self.session.apply(changes)
            return {**self.session.state(), "refused": refused}
        return web.json_response(await self.work(run))

    async def set_(self, request):
        """POST `/api/set` `{changes: {key: value or null}}`: the state."""
        body = await _body(request)
        changes = body.get("changes")

        def run():
            self.session.set(changes)
            return self.session.state()
        return web.json_response(await self.work(run))

    async def undo(self, request):
        """POST `/api/undo`: the state."""
        return await self._stepped(self.session.undo)

    async def redo(self, request):
        """POST `/api/redo`: the state."""
        return await self._stepped(self.session.redo)

    async def _stepped(self, step):
        """`step` (undo or redo) on the worker: the state after it."""
        def run():
            step()
            return self.session.state()
        return web.json_response(await self.work(run))

    async def pick(self, request):
        """POST `/api/pick` `{x, y}` (image pixels): the nearest vertex."""
        body = await _body(request)
        return web.json_response(await self.work(self.session.pick, body.get("x"),
                                                 body.get("y")))

    async def fields(self, request):
        """GET `/api/fields?step=`: the arrows and the edits' markers."""
        try:
            step = int(request.query.get("step", "24"))
        except ValueError:
            raise EditorError("step: expected an integer", 400) from None
        if not 4 <= step <= 256:
            raise EditorError("step: expected an integer in [4, 256]", 400)
        return web.json_response(await self.work(self.session.fields, step))

    async def paint(self, request):
        """POST `/api/paint` `{stroke, layer, points, radius, strength, erase}`: `{dabs}`,
        with the version and the seconds it took."""
        body = await _body(request)
        args = {k: body.get(k) for k in ("stroke", "layer", "points", "radius", "strength")}
        if not isinstance(args["stroke"], str) or not isinstance(args["layer"], str):
            raise EditorError("expected {stroke: id, layer: name, points: [[x, y], ...], "
                              "radius, strength, erase}", 400)
        t0 = time.perf_counter()
        out = await self.work(self.session.paint_stroke, erase=bool(body.get("erase", False)),
                              **args)
        return web.json_response({**out, "version": self.session.version,
                                  "seconds": time.perf_counter() - t0})

    async def render(self, request):
        """GET `/api/render?client=&preview=1`: the view as `image/png` (a preview:
        `image/bmp`); 409 `superseded` when a newer request of the same client came
        before this one started."""
        client = request.query.get("client", "")[:100]
        preview = request.query.get("preview", "0") == "1"
        with self.lock:
            n = next(self.counter)
            self.latest[client] = n
        out = await self.work(self._image, client, n, preview)
        if out is None:
            return web.json_response({"error": "superseded by a newer render request",
                                      "superseded": True}, status=409)
        data, kind, seconds, version = out
        return web.Response(body=data, content_type=kind, headers={
            "Cache-Control": "no-store", "X-Render-Seconds": f"{seconds:.4f}",
            "X-Version": str(version)})

    def _image(self, client: str, n: int, preview: bool):
        """On the worker: render request `n`'s image `(bytes, type, seconds, version)`,
        made again only when the view changed; None when `client` asked again since."""
        if self.latest.get(client) != n:
            return None
        key = (self.session.version, preview)
        if self.cache.get("key") != key:
            t0 = time.perf_counter()
            data, kind = self.session.image_file(preview)
            self.cache.update(key=key, data=data, kind=kind, seconds=time.perf_counter() - t0)
        return (self.cache["data"], self.cache["kind"], self.cache["seconds"],
                self.session.version)

    async def save(self, request):
        """POST `/api/save` `{name, overwrite?}`: the files written, and the state."""
        body = await _body(request)
        name = body.get("name")
        overwrite = body.get("overwrite", False)
        if not isinstance(name, str) or not isinstance(overwrite, bool):
            raise EditorError("expected {name: a file name, overwrite: true or false}", 400,
                              "name")

        def run():
            written = self.session.save(name, overwrite)
            return {"written": written, **self.session.state()}
        return web.json_response(await self.work(run))

    async def upload(self, request):
        """POST `/api/upload?name=` with the file's bytes: `{path}`, kept in the output
        folder."""
        name = request.query.get("name", "")
        data = await request.read()
        path = await self.work(self.session.upload, name, data)
        return web.json_response({"path": path})
