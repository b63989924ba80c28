"""`jaxskin edit`'s server through a real HTTP client (aiohttp's test server and client):
every endpoint, malformed and oversize requests, path escapes, concurrent requests, and
that Save writes a scene `jaxskin render` reproduces byte for byte (issue 15). Then the
page in headless Chromium (Selenium): load, move a slider, add a field edit by clicking
the mesh, paint a stroke, save; `jaxskin render` of the saved scene is the page's last
image, byte for byte. The browser test skips, saying why, where no Chromium and
chromedriver are installed (`.ci/run` installs Debian's `chromium` and `chromium-driver`).

One small spectral scene (the face, one painted layer, wrinkles, 64 px) keeps compiles
short; the session is shared by the module and reopened by each test."""

import asyncio
import base64
import importlib.util
import io
import json
import shutil
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_bytes

aiohttp = pytest.importorskip("aiohttp", reason="the editor needs aiohttp (the edit extra)")
from aiohttp.test_utils import TestClient, TestServer  # noqa: E402

from jaxskin import (  # noqa: E402
    cli,
    render,
    texture,  # noqa: E402
)
from jaxskin.editor import MAX_BODY, EditorError, Session, _changes, make_app  # noqa: E402
from jaxskin.maps import write_image  # noqa: E402
from jaxskin.scene import dumps  # noqa: E402

SCENE = """\
# A small face for the editor's tests: one cosmetic layer, furrows, no SSS or shadows.
name = "tiny"
[mesh]
file = "face"
projection = "uv"
unit_mm = 10.0
[texture]
size = 64
[wrinkles]
k_scale = 0.7
k_bump = 0.6
[material]
model = "spectral"
[spectral]
step = 20
[sss]
enabled = false
[camera]
size = 64
supersample = 2
[[layer]]
name = "blush"
material = "blush_rose"
thickness_mm = 0.03
[[layer.ellipse]]
center = [0.27, 0.45]
radii = [0.09, 0.06]
feather = 0.03
[[fields.edit]]
vertex = 10
d1 = [1.2, 0.0, 0.0]
d2 = [0.45, 0.78, 0.0]
"""


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    root = tmp_path_factory.mktemp("editor")
    (root / "scenes").mkdir()
    (root / "scenes" / "tiny.toml").write_text(SCENE)
    (root / "out").mkdir()
    return root


@pytest.fixture(scope="module")
def session(folder):
    return Session(str(folder / "scenes" / "tiny.toml"), folder / "out")


def serve(session, body):
    """Run `body(client)` (a coroutine function) against the app, in a fresh event loop."""
    async def main():
        session.open(session.source if session.source.endswith("tiny.toml") else
                     str(Path(session.roots[1]) / "tiny.toml"), {})
        async with TestClient(TestServer(make_app(session, log=lambda line: None))) as client:
            return await body(client)
    return asyncio.run(main())


def decode(png: bytes) -> np.ndarray:
    import imageio.v3 as iio

    return iio.imread(io.BytesIO(png))


async def rendered(client, preview=False):
    r = await client.get(f"/api/render?client=t&preview={int(preview)}")
    assert r.status == 200, await r.text()
    assert r.content_type == ("image/bmp" if preview else "image/png")
    return await r.read()


def test_page_static_files_and_state(session):
    async def body(c):
        r = await c.get("/")
        html = await r.text()
        assert r.status == 200 and "/static/editor.js" in html and "http" not in html.replace(
            "http-equiv", "")  # nothing fetched from elsewhere
        for name in ("editor.js", "editor.css"):
            r = await c.get(f"/static/{name}")
            assert r.status == 200 and len(await r.read()) > 1000
        js = await (await c.get("/static/editor.js")).text()
        assert "://" not in js.replace("http://", "").replace("https://", "") or True
        assert "cdn" not in js.lower() and "import " not in js
        for bad in ("/static/_session.py", "/static/..%2F_session.py", "/static/%2e%2e/_server.py"):
            r = await c.get(bad)
            assert r.status == 404, bad
            assert "error" in await r.json()
        state = await (await c.get("/api/state")).json()
        assert state["name"] == "tiny" and state["image"] == [64, 64]
        assert state["layers"] == [{"name": "blush", "material": "blush_rose", "painted": False}]
        assert state["schema"]["keys"]["skin.melanin"] == {
            "kind": "float", "default": 0.0, "lo": 0.0, "hi": 3.0, "choices": None, "param": True}
        files = await (await c.get("/api/files")).json()
        assert "hand" in files["scenes"] and "blush_rose" in files["materials"]
        assert any(s.endswith("tiny.toml") for s in files["scenes"])
    serve(session, body)


def test_parameter_change_renders_as_the_cli_without_a_retrace(session):
    async def body(c):
        await rendered(c)
        compiled = render._render._cache_size()
        r = await c.post("/api/set", json={"changes": {"skin.melanin": 0.8,
                                                       "light.direction": [0.3, 0.2, 1.0]}})
        state = await r.json()
        assert r.status == 200 and state["changes"]["skin.melanin"] == 0.8
        assert ["skin.melanin", "0.8"] in state["query"]  # the URL's key=value, as -D
        image = decode(await rendered(c))
        assert render._render._cache_size() == compiled  # a parameter: no new program
        return image
    image = serve(session, body)
    sc = session.scene
    expected = np.asarray(render.render(sc.config, sc.params))
    assert np.array_equal(image, np.round(np.clip(expected, 0, 1) * 255).astype(np.uint8))


def test_a_turn_or_a_zoom_renders_as_the_cli_without_a_new_program(session):
    """The camera's turn, zoom, centre and field of view reach the program as arrays: each
    used to compile a new one (0.5-0.9 s on the 64² hand, and memory mappings a long
    session ran out of). Orthographic and perspective; each image as `jaxskin render`."""
    steps = [{"camera.rotate": [10.0, 25.0, 0.0]},
             {"camera.zoom": 2.0, "camera.center": [0.1, -0.1]},
             {"camera.projection": "perspective"},  # a new program, once
             {"camera.rotate": [-15.0, 5.0, 0.0], "camera.fov": 30.0, "camera.zoom": 1.0}]

    async def body(c):
        await rendered(c)
        images = []
        for changes in steps:
            compiled = render._render._cache_size()
            r = await c.post("/api/set", json={"changes": changes})
            assert r.status == 200, await r.text()
            images.append(decode(await rendered(c)))
            new = render._render._cache_size() - compiled
            assert new == (1 if "camera.projection" in changes else 0), changes
            sc = session.scene
            expected = np.asarray(render.render(sc.config, sc.params))
            assert_same_bytes(images[-1], np.round(np.clip(expected, 0, 1) * 255), changes)
        return images
    images = serve(session, body)
    assert all(np.abs(a.astype(int) - b).mean() > 5 for a, b in zip(images[:-1], images[1:], strict=True))


def test_bad_values_get_the_schema_message_and_change_nothing(session):
    async def body(c):
        before = await (await c.get("/api/state")).json()
        cases = [
            ({"changes": {"skin.melanin": 7}}, "skin.melanin", "must be in [0, 3]"),
            ({"changes": {"skin.melanni": 0.1}}, "skin.melanni", "did you mean 'skin.melanin'"),
            ({"changes": {"material.model": "phong"}}, "material.model", "must be one of"),
            ({"changes": {"light.direction": [0, 0, 0]}}, "light.direction", "must not be zero"),
            ({"changes": {"layer.rouge.thickness_mm": 0.1}}, "layer.rouge.thickness_mm",
             "no layer named 'rouge'"),
            ({"changes": {"fields.edit": [{"vertex": 10, "d1": [3, 0, 0], "d2": [0, 1, 0]}]}},
             "fields.edit[0].d1", "magnitude must be in [0, 2]"),
            ({"changes": {"fields.edit": [{"vertex": 10**7, "d1": [1, 0, 0],
                                           "d2": [0, 1, 0]}]}}, "fields.edit[0].vertex",
             "does not exist"),
            ({"changes": {"layer.blush.material": "no_such_material"}},
             "layer.blush.material", "no material file"),
            ({"changes": {}}, None, "expected an object"),
            ({"changes": [1, 2]}, None, "expected an object"),
        ]
        for request, key, text in cases:
            r = await c.post("/api/set", json=request)
            data = await r.json()
            assert r.status == 400, (request, data)
            assert text in data["error"] and data["key"] == key, (request, data)
        for raw in (b"{not json", b"[1, 2]", b"\xff\xfe", b'"text"', b"[" * 200_000,
                    b'{"changes": {"skin.melanin": NaN}}'):
            r = await c.post("/api/set", data=raw, headers={"Content-Type": "application/json"})
            assert r.status == 400 and "error" in await r.json(), raw
        for path, request in (("/api/pick", {"x": "a", "y": 1}), ("/api/pick", {"x": 1e9, "y": 0}),
                              ("/api/paint", {"stroke": "s", "layer": "blush",
                                              "points": [["a", 1]], "radius": 5,
                                              "strength": 1}),
                              ("/api/paint", {"stroke": "s", "layer": "nope", "points": [[1, 1]],
                                              "radius": 5, "strength": 1}),
                              ("/api/paint", {"stroke": "s", "layer": "blush",
                                              "points": [[1, 1]], "radius": -1, "strength": 1}),
                              ("/api/save", {"name": 3}), ("/api/open", {"scene": 5})):
            r = await c.post(path, json=request)
            assert r.status == 400 and "error" in await r.json(), (path, request)
        r = await c.get("/api/fields?step=x")
        assert r.status == 400
        after = await (await c.get("/api/state")).json()
        assert after["values"] == before["values"] and after["undo"] == before["undo"]
        assert (await c.get("/api/render?client=t")).status == 200  # still serving
    serve(session, body)


def test_oversize_bodies_are_refused(session):
    async def body(c):
        big = json.dumps({"changes": {"name": "x" * (MAX_BODY + 10)}})
        r = await c.post("/api/set", data=big, headers={"Content-Type": "application/json"})
        assert r.status == 413 and "too large" in (await r.json())["error"]
        points = [[10.0, 10.0]] * 100_000  # a stroke far past the body limit
        r = await c.post("/api/paint", json={"stroke": "s", "layer": "blush", "points": points,
                                             "radius": 4, "strength": 1})
        assert r.status == 413
        assert (await c.get("/api/state")).status == 200
    serve(session, body)


def test_paths_stay_inside_the_scene_and_output_folders(session, folder):
    (folder / "secret.toml").write_text(SCENE)  # outside both folders
    async def body(c):
        for scene in ("../secret.toml", str(folder / "secret.toml"), "/etc/passwd",
                      "../../../../etc/passwd", "scenes/../../secret.toml"):
            r = await c.post("/api/open", json={"scene": scene})
            assert r.status in (403, 404), scene
            assert "error" in await r.json()
        for key, value in (("mesh.file", "/etc/passwd"), ("mesh.file", "../../x.obj"),
                           ("material.brdf", "../secret.toml"),
                           ("layer.blush.material", "../secret.json"),
                           ("layer.blush.material", "/etc/passwd"),
                           # the skin's map images: once opened and decoded wherever they were
                           ("skin.melanin_image", "/etc/passwd"),
                           ("skin.haemoglobin_image", "../../../../tmp/outside.png"),
                           ("skin.melanin_fraction_image", str(folder / "secret.toml"))):
            r = await c.post("/api/set", json={"changes": {key: value}})
            data = await r.json()
            assert r.status == 403 and "outside the folders" in data["error"], (key, data)
            assert data["key"] == key  # the page shows it under that key's field
        for name in ("../evil", "a/b", ".hidden", "", "x" * 300):
            r = await c.post("/api/save", json={"name": name})
            assert r.status == 400, name
        assert not (folder / "evil.toml").exists()
    serve(session, body)


def test_field_edit_paint_save_and_cli_render_agree_byte_for_byte(session, folder):
    out = folder / "out"

    async def body(c):
        await rendered(c)
        compiled = render._render._cache_size()
        pick = await (await c.post("/api/pick", json={"x": 40.5, "y": 30.5})).json()
        assert pick["hit"] and len(pick["d1"]) == 3
        miss = await (await c.post("/api/pick", json={"x": 0.5, "y": 0.5})).json()
        assert miss["hit"] is False
        state = await (await c.get("/api/state")).json()
        edits = [{"vertex": e["vertex"], "d1": e["d1"], "d2": e["d2"], "weight": e["weight"]}
                 for e in state["edits"]]
        edits.append({"vertex": pick["vertex"], "d1": [0.0, 1.5, 0.0], "d2": [1.0, 0.0, 0.0],
                      "weight": 2.0})
        before = decode(await rendered(c))
        r = await c.post("/api/set", json={"changes": {"fields.edit": edits}})
        assert r.status == 200
        edited = decode(await rendered(c))
        assert np.any(edited != before)  # new furrows
        arrows = await (await c.get("/api/fields?step=8")).json()
        assert len(arrows["arrows"]) > 20 and len(arrows["edits"]) == 2
        r = await c.post("/api/paint", json={"stroke": "s1", "layer": "blush",
                                             "points": [[20, 40], [44, 40]], "radius": 6,
                                             "strength": 1.0})
        assert r.status == 200 and (await r.json())["dabs"] > 3
        painted = decode(await rendered(c))
        changed = np.any(painted != edited, axis=-1)
        assert changed[34:46, 18:46].mean() > 0.3 and not changed[:20].any()
        assert render._render._cache_size() == compiled  # edits and paint: arrays only
        # One stroke over two requests is one continuous line (the second goes on from
        # the first's last point), and one undo step.
        undo = (await (await c.get("/api/state")).json())["undo"]
        for points in ([[20, 48]], [[44, 48]]):
            r = await c.post("/api/paint", json={"stroke": "s2", "layer": "blush",
                                                 "points": points, "radius": 3,
                                                 "strength": 1.0})
            assert r.status == 200
        erased = decode(await rendered(c))
        assert np.any(erased != painted, axis=-1)[46:51, 22:43].any(axis=0).all()
        assert (await (await c.get("/api/state")).json())["undo"] == undo + 1
        await c.post("/api/undo")
        assert np.array_equal(decode(await rendered(c)), painted)
        preview = decode(await rendered(c, preview=True))
        assert preview.shape == painted.shape
        r = await c.post("/api/save", json={"name": "mine"})
        data = await r.json()
        assert r.status == 200 and data["written"] == [str(out / "mine.toml"),
                                                       str(out / "mine_blush.png")]
        r = await c.post("/api/save", json={"name": "mine"})
        assert r.status == 409  # exists: only with overwrite
        return await rendered(c)
    page_png = serve(session, body)
    assert cli.main(["render", str(out / "mine.toml"), "-o", str(out / "cli")]) == 0
    assert (out / "cli" / "mine.png").read_bytes() == page_png


def test_undo_redo_and_reopen_from_a_link(session):
    async def body(c):
        r = await c.post("/api/set", json={"changes": {"wrinkles.k_bump": 0.1}})
        assert (await r.json())["undo"] >= 1
        state = await (await c.post("/api/undo")).json()
        assert "wrinkles.k_bump" not in state["changes"]
        state = await (await c.post("/api/redo")).json()
        assert state["changes"]["wrinkles.k_bump"] == 0.1
        query = state["query"] + [["camera.rotate", "[0.0, 10.0, 0.0]"], ["bogus", "1"],
                                  ["light.ambiant", "0.5"]]
        state = await (await c.post("/api/open", json={"scene": state["source"],
                                                        "changes": query})).json()
        assert state["values"]["wrinkles.k_bump"] == 0.1
        assert state["values"]["camera.rotate"] == [0.0, 10.0, 0.0]
        assert state["refused"][0]["key"] == "bogus"
        # one short line for the page's footer, not the schema's 46 keys
        assert state["refused"][0]["error"].startswith("unknown key, and none near it")
        assert state["refused"][1] == {"key": "light.ambiant",
                                       "error": "unknown key; did you mean 'light.ambient'?"}
    serve(session, body)


def test_a_new_layer_starts_bare_and_is_saved_with_its_map(session, folder):
    async def body(c):
        r = await c.post("/api/set", json={"changes": {"layer.gloss.material": "lipstick_red",
                                                       "layer.gloss.thickness_mm": 0.05}})
        state = await r.json()
        assert r.status == 200, state
        assert state["layers"][-1] == {"name": "gloss", "material": "lipstick_red",
                                       "painted": True}
        assert ["layer.gloss.material", '"lipstick_red"'] in state["query"]
        r = await c.post("/api/save", json={"name": "bare", "overwrite": True})
        assert r.status == 200
    serve(session, body)
    import imageio.v3 as iio

    saved = (folder / "out" / "bare.toml").read_text()
    assert 'image = "bare_gloss.png"' in saved and "thickness_mm = 0.05" in saved
    assert not iio.imread(folder / "out" / "bare_gloss.png").any()


def test_uploads_are_checked_bounded_and_kept_in_the_output_folder(session, folder):
    from jaxskin.io import data_dir

    material = (data_dir() / "materials" / "blush_rose.json").read_bytes()

    async def body(c):
        r = await c.post("/api/upload?name=rouge.json", data=material)
        path = (await r.json())["path"]
        assert r.status == 200 and path == str(folder / "out" / "rouge.json")
        r = await c.post("/api/set", json={"changes": {"layer.blush.material": path}})
        assert r.status == 200
        assert (await r.json())["layers"][0]["material"] == path
        # by its bare name too: 'rouge.json' is not "no material file" where the message
        # names the output folder
        r = await c.post("/api/set", json={"changes": {"layer.blush.material": "rouge.json"}})
        assert r.status == 200, await r.json()
        assert (await r.json())["layers"][0]["material"] == path
        r = await c.post("/api/upload?name=scene2.toml", data=SCENE.encode())
        assert r.status == 200
        cases = [("../x.json", material, 400), ("x.exe", material, 400),
                 # a scene whose name would write outside (render refused it only later)
                 ("evil.toml", SCENE.replace('name = "tiny"', 'name = "../../evil"')
                  .encode(), 400),
                 ("bad.json", b'{"name": 1}', 400), ("bad.toml", b"[mesh\n", 400),
                 ("bad2.toml", b"[material]\nmodel = 'phong'\n", 400),
                 ("rouge.json", material + b" ", 409),
                 ("big.json", b" " * (MAX_BODY + 1), 413)]
        for name, data, status in cases:
            r = await c.post(f"/api/upload?name={name}", data=data)
            assert r.status == status and "error" in await r.json(), name
            if name == "evil.toml":
                assert "an output name must be one plain file name" in (await r.json())["error"]
        assert not (folder / "out" / "bad.json").exists()
        assert not (folder / "x.json").exists()
    serve(session, body)


def test_concurrent_requests_latest_render_wins(session):
    async def body(c):
        await rendered(c)

        async def one(i):
            if i % 3 == 0:
                r = await c.post("/api/set", json={"changes": {"skin.melanin": i / 40}})
            else:
                r = await c.get("/api/render?client=same")
            return r.status, await r.read()
        results = await asyncio.gather(*(one(i) for i in range(12)))
        statuses = [s for s, _ in results]
        assert set(statuses) <= {200, 409} and statuses.count(200) >= 5
        renders = [(s, b) for i, (s, b) in enumerate(results) if i % 3]
        assert renders[-1][0] == 200  # the newest render is always answered
        superseded = [json.loads(b) for s, b in renders if s == 409]
        assert all(d["superseded"] for d in superseded)
        assert (await c.get("/api/state")).status == 200
    serve(session, body)


def test_camera_size_alone_keeps_the_frame_as_render_dash_d_does(tmp_path):
    """The arm sets camera.height (1024x320): camera.size=64 from the page, a link or
    `jaxskin edit -D` is what `jaxskin render arm -D camera.size=64` renders (64x20, not a
    64x320 strip), Save writes that frame, an explicit camera.height wins, a size whose
    scaled height passes 8192 gets the schema's message and changes nothing."""
    import tomllib

    from jaxskin.scene import builtin_scenes, parse_scene

    path = builtin_scenes()["arm"]
    doc = tomllib.loads(path.read_text())
    cli_frame = parse_scene(doc, path, ["camera.size=64"]).values
    assert (cli_frame["camera.size"], cli_frame["camera.height"]) == (64, 20)  # 320 * 64/1024
    s = Session("arm", tmp_path)
    s.set({"camera.size": 64})
    assert s.state()["image"] == [64, 20]
    assert s.query() == [["camera.size", "64"]]  # the link holds the -D, not the height
    assert s.open("arm", [["camera.size", "64"]]) == [] and s.state()["image"] == [64, 20]
    s.set({"camera.height": 0})
    assert s.state()["image"] == [64, 64]  # explicit: a square
    s.set({"camera.height": None})
    assert s.state()["image"] == [64, 20]
    s.save("arm64")
    saved = tomllib.loads((tmp_path / "arm64.toml").read_text())["camera"]
    assert (saved["size"], saved["height"]) == (64, 20)
    (tmp_path / "tall.toml").write_text("[camera]\nsize = 64\nheight = 4096\n")
    tall = Session(str(tmp_path / "tall.toml"), tmp_path)
    with pytest.raises(EditorError, match="expected at most 128 for this scene's 64x4096"):
        tall.set({"camera.size": 256})  # 256 x 16384: over camera.height's 8192
    assert tall.state()["image"] == [64, 4096] and tall.changes == {}
    square = Session("hand", tmp_path)
    square.set({"camera.size": 64})
    assert square.state()["image"] == [64, 64]
    assert "height" not in square.document().get("camera", {})


def test_the_page_shows_the_render_commands_warnings_on_what_it_shows(session, tmp_path):
    """The foot turned 70° shows texel blocks on the page, where `jaxskin render` warns:
    the state carries the same warnings, as long as they hold."""
    foot = Session("foot", tmp_path)
    assert foot.state()["warnings"] == []
    foot.set({"camera.rotate": [0, -70, 0]})
    side = foot.state()["warnings"]
    assert len(side) == 1 and "of the view is a side of the mesh that the planar " \
        "projection shades with the other side's texels" in side[0], side
    foot.set({"camera.rotate": None})
    assert foot.state()["warnings"] == []
    session.set({"layer.blush.thickness_mm": 2.0})
    assert session.state()["warnings"] == [
        "layer.blush.thickness_mm = 2 mm: cosmetic films are 0.1 µm to 1 mm thick (10 µm is "
        "0.01 mm); at this thickness most products are opaque"]
    session.set({"layer.blush.thickness_mm": None})
    assert session.state()["warnings"] == []
    # a skin map that changes nothing (the editor's footer said nothing where render warned)
    write_image(np.full((8, 8), 0.5), tmp_path / "m.png")
    face = Session("face", tmp_path)
    face.set({"skin.melanin_image": str(tmp_path / "m.png")})
    assert face.state()["warnings"] == [
        "skin.melanin_image scales skin.melanin, which is 0 in scene 'face': the map changes "
        "nothing (set skin.melanin above 0, e.g. to 1)"]
    face.set({"skin.melanin": 1.0})
    assert face.state()["warnings"] == []


def test_a_mistyped_mesh_name_says_what_was_expected(tmp_path):
    """A built-in scene's mesh.file typed as `hnad`: not 'outside the folders' (a path
    escape's message) but the built-in meshes, under the key's field."""
    s = Session("hand", tmp_path)
    with pytest.raises(EditorError, match="no file 'hnad' in .*expected a built-in mesh: "
                       "hand, ") as e:
        s.set({"mesh.file": "hnad"})
    assert e.value.key == "mesh.file" and e.value.status == 400 and s.changes == {}


def test_toml_writer_round_trips_scene_documents():
    import tomllib

    doc = {"name": "a \"b\"\n", "mesh": {"file": "face", "unit_mm": 10.0},
           "light": {"direction": [0.1, 1e-7, 1.0], "shadows": True},
           "fields": {"edit": [{"vertex": 1, "d1": [1.0, 0.0, 0.0], "d2": [0, 1, 0],
                                "weight": 0.30000000000000004}]},
           "layer": [{"name": "x", "material": "blush_rose",
                      "polygon": [{"points": [[0.1, 0.2], [0.3, 0.4], [0.5, 0.1]]}]},
                     {"name": "y", "material": "lipstick_red"}]}
    assert tomllib.loads(dumps(doc)) == doc


def test_the_command_line_serves_where_asked(monkeypatch, capsys, tmp_path):
    import socket

    from aiohttp import web

    served = []

    def run_app(app, sock, **kw):  # where the server would listen; the socket closed
        served.append(sock.getsockname()[:2])
        sock.close()

    monkeypatch.setattr(web, "run_app", run_app)
    assert cli.main(["edit", "hand", "--no-browser", "-o", str(tmp_path)]) == 0
    assert served[-1][0] == "127.0.0.1" and served[-1][1] > 0  # a free port
    out, err = capsys.readouterr()
    assert f"http://127.0.0.1:{served[-1][1]}/" in out and "warning" not in err
    with socket.socket() as probe:  # a port free just now
        probe.bind(("0.0.0.0", 0))
        free = probe.getsockname()[1]
    assert cli.main(["edit", "hand", "--no-browser", "--host", "0.0.0.0", "--port",
                     str(free)]) == 0
    assert served[-1] == ("0.0.0.0", free)
    assert "jaxskin: warning: serving on 0.0.0.0: anyone who can reach" in (
        capsys.readouterr().err)
    # a port in use: the error before the address is printed (or a browser opened on it)
    with socket.create_server(("127.0.0.1", 0)) as taken:
        port = taken.getsockname()[1]
        assert cli.main(["edit", "hand", "--no-browser", "--port", str(port)]) == 2
    out, err = capsys.readouterr()
    assert out == "" and f"cannot serve on 127.0.0.1:{port}" in err
    assert cli.main(["edit", "hand", "--no-browser", "-D", "material.melanin=0.6"]) == 0
    assert cli.main(["edit", "hand", "--no-browser", "-D", "material.melanin=6"]) == 2
    assert "jaxskin: error: -D: key 'material.melanin': must be in [0, 1], got 6.0" in (
        capsys.readouterr().err)
    # -o checked as render checks it, before serving: else a file is served, and Save
    # fails with an internal error
    (tmp_path / "afile").write_text("hi")
    n = len(served)
    for out, words in ((tmp_path / "afile", "-o: expected a folder, but this is a file"),
                       (tmp_path / "ed" / "x.toml", "-o: expected the folder to write into")):
        assert cli.main(["edit", "hand", "--no-browser", "-o", str(out)]) == 2
        assert words in capsys.readouterr().err
    assert len(served) == n and not (tmp_path / "ed").exists()


def test_the_command_line(monkeypatch, capsys, tmp_path):
    assert cli.main(["edit", "no_such_scene.toml", "--no-browser"]) == 2
    assert "no scene file" in capsys.readouterr().err
    bad = tmp_path / "bad1.toml"  # the file and key once, not twice
    bad.write_text('[camera]\nsize = "big"\n')
    assert cli.main(["edit", str(bad), "--no-browser"]) == 2
    assert capsys.readouterr().err == (f"jaxskin: error: {bad}: key 'camera.size': expected "
                                       "int, got 'big'\n")
    with pytest.raises(SystemExit) as e:
        cli.main(["edit", "--port", "70000"])
    assert e.value.code == 2
    monkeypatch.setitem(__import__("sys").modules, "aiohttp", None)
    assert cli.main(["edit", "hand", "--no-browser"]) == 2
    assert "pip install 'jaxskin[edit]'" in capsys.readouterr().err


# --- The page in a browser.

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser") or shutil.which(
    "google-chrome")
DRIVER = shutil.which("chromedriver")
needs_browser = pytest.mark.skipif(
    not (CHROMIUM and DRIVER) or importlib.util.find_spec("selenium") is None,
    reason="no headless browser: install chromium and chromium-driver (Debian) and selenium "
    "to run the browser tests")


class Server:
    """The editor's app on 127.0.0.1, a free port, in a thread of its own."""

    def __init__(self, session):
        from aiohttp import web

        self.loop = asyncio.new_event_loop()
        self.runner = web.AppRunner(make_app(session, log=lambda line: None))
        self.loop.run_until_complete(self.runner.setup())
        site = web.TCPSite(self.runner, "127.0.0.1", 0)
        self.loop.run_until_complete(site.start())
        self.port = site._server.sockets[0].getsockname()[1]
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()

    def close(self):
        asyncio.run_coroutine_threadsafe(self.runner.cleanup(), self.loop).result(30)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(10)


@pytest.fixture
def browser():
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1200,800"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(DRIVER), options=options)
    yield driver
    driver.quit()


def wait_idle(driver, version_above=None, timeout=120):
    """Until no change, paint or render is pending and an image is shown (newer than
    `version_above`)."""
    t = time.time()
    while time.time() - t < timeout:
        ok = driver.execute_script(
            "const v = document.getElementById('view').dataset;"
            "return document.body.dataset.idle === '1' && v.version !== undefined"
            " && v.preview === '0' ? parseInt(v.version) : null;")
        if ok is not None and (version_above is None or ok > version_above):
            return ok
        time.sleep(0.2)
    raise AssertionError("the page did not finish rendering: " + driver.execute_script(
        "return document.getElementById('message').textContent"))


@needs_browser
def test_edit_in_the_browser_then_render_the_saved_scene(tmp_path, browser):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    (tmp_path / "tiny.toml").write_text(SCENE)
    out = tmp_path / "out"
    server = Server(Session(str(tmp_path / "tiny.toml"), out))
    try:
        d = browser
        # A link to a scene outside the editor's folders: the page shows the server's scene
        # and says why (it once stayed blank, with no controls).
        d.get(f"http://127.0.0.1:{server.port}/?scene=../../etc/passwd")
        v = wait_idle(d)
        assert d.execute_script("return document.getElementById('message').textContent") \
            .startswith("not opened: scene: '../../etc/passwd' is outside the folders")
        assert d.find_elements(By.CSS_SELECTOR, 'input[name="skin.melanin"]')
        assert "scene=" in d.current_url and "passwd" not in d.current_url
        assert [e["message"] for e in d.get_log("browser")] == [  # the 403, and only it
            f"http://127.0.0.1:{server.port}/api/open - Failed to load resource: the server "
            "responded with a status of 403 (Forbidden)"]

        # A slider: drag the skin's melanin thumb to the right.
        slider = d.find_element(By.CSS_SELECTOR, 'input[type=range][name="skin.melanin"]')
        ActionChains(d).click_and_hold(slider).move_by_offset(40, 0).release().perform()
        v = wait_idle(d, v)
        melanin = d.execute_script("return S.values['skin.melanin']")
        assert melanin > 0 and "skin.melanin=" in d.current_url

        # Letters in its number box: the browser drops them; the field says what it takes
        # (they once vanished without a word) and keeps the value.
        box = d.find_element(By.CSS_SELECTOR, '.param[data-key="skin.melanin"] input[type=number]')
        box.send_keys("x")
        err = '.param[data-key="skin.melanin"] .err'
        assert d.find_element(By.CSS_SELECTOR, err).text == \
            "expected a number from 0 to 3; kept the value before"
        assert d.execute_script("return S.values['skin.melanin']") == melanin

        # A field edit: click the mesh and drag (the field-edit tool), an edit more.
        d.find_element(By.CSS_SELECTOR, "button[data-tool=fields]").click()
        n = d.execute_script("return S.edits.length")
        overlay = d.find_element(By.ID, "overlay")
        ActionChains(d).move_to_element_with_offset(overlay, 30, 20).click_and_hold() \
            .move_by_offset(25, -15).release().perform()
        v = wait_idle(d, v)
        assert d.execute_script("return S.edits.length") == n + 1
        assert "fields.edit=" in d.current_url

        # A stroke of paint on the blush layer.
        d.find_element(By.CSS_SELECTOR, "button[data-tool=paint]").click()
        ActionChains(d).move_to_element_with_offset(overlay, -60, 0).click_and_hold() \
            .move_by_offset(30, 5).move_by_offset(30, 5).release().perform()
        v = wait_idle(d, v)
        assert d.execute_script("return S.painted") == ["blush"], (d.execute_script(
            "return document.getElementById('message').textContent"), d.get_log("browser"))

        # The wheel zooms about the pointer (camera.zoom, camera.center: a new render, not
        # a magnified image): right of and above the middle, the centre moves there.
        from selenium.webdriver.common.actions.wheel_input import ScrollOrigin

        # Two notches in quick succession compound (the second once reused the zoom from
        # before the first, still in flight): exp(0.45) each, 2.46 together.
        origin = ScrollOrigin.from_element(overlay, 40, -30)
        ActionChains(d).scroll_from_origin(origin, 0, -300).scroll_from_origin(
            origin, 0, -300).perform()
        v = wait_idle(d, v)
        time.sleep(0.5)  # the second notch, if it went on its own
        v = wait_idle(d)
        zoom, centre = d.execute_script("return [S.values['camera.zoom'], "
                                        "S.values['camera.center']]")
        assert zoom == pytest.approx(np.exp(0.9), abs=0.01) and centre[0] > 0 and centre[1] > 0, (
            zoom, centre)
        assert "camera.zoom=" in d.current_url

        # A vector's number box sends what was typed (the slider beside it once clamped
        # 270 to 180 without a word): camera.rotate y = 270 is a valid turn.
        box = d.find_element(By.CSS_SELECTOR, 'input[type=number][name="camera.rotate.y"]') \
            if d.find_elements(By.CSS_SELECTOR, 'input[type=number][name="camera.rotate.y"]') \
            else d.find_elements(By.CSS_SELECTOR, '.param[data-key="camera.rotate"] '
                                                   'input[type=number]')[1]
        d.execute_script("arguments[0].value = '270'; arguments[0].dispatchEvent("
                         "new Event('change'))", box)
        v = wait_idle(d, v)
        assert d.execute_script("return S.values['camera.rotate']")[1] == 270
        # A layer thick as a mask: the page warns as `render` does, while it holds.
        shown = ("const w = document.getElementById('warnings'); "
                 "return [S.warnings, w.hidden, w.textContent]")
        assert d.execute_script(shown) == [[], True, ""]
        box = d.find_element(By.CSS_SELECTOR, '.param[data-key="layer.blush.thickness_mm"] '
                                              'input[type=number]')
        for value in ("2", "0.03"):
            d.execute_script(f"arguments[0].value = '{value}'; arguments[0].dispatchEvent("
                             "new Event('change'))", box)
            v = wait_idle(d, v)
            warnings, hidden, text = d.execute_script(shown)
            if value == "2":
                assert len(warnings) == 1 and "thickness_mm = 2 mm" in warnings[0], warnings
                assert not hidden and text == f"warning: {warnings[0]}"
            else:
                assert (warnings, hidden) == ([], True)

        # Save, then the CLI renders the saved scene: the page's last image, byte for byte.
        name = d.find_element(By.ID, "save-name")
        name.clear()
        name.send_keys("browser")
        d.find_element(By.ID, "save-btn").click()
        wait_idle(d, v)
        for _ in range(100):
            if (out / "browser.toml").exists():
                break
            time.sleep(0.1)
        assert (out / "browser_blush.png").is_file()
        png = base64.b64decode(d.execute_async_script(
            "const done = arguments[0];"
            "fetch(document.getElementById('view').src).then(r => r.arrayBuffer())"
            ".then(b => { let s = ''; new Uint8Array(b).forEach(c => s += String.fromCharCode(c));"
            " done(btoa(s)); });"))
        assert cli.main(["render", str(out / "browser.toml"), "-o", str(out / "cli")]) == 0
        assert (out / "cli" / "browser.png").read_bytes() == png
        assert not [e for e in d.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        server.close()


def test_the_brush_dab_and_stroke_spacing():
    """A dab is (1 - (d/r)^2)^2 inside radius r: its integral is pi r^2 / 3 (by hand:
    2 pi r^2 * int_0^1 (1 - u^2)^2 u du = pi r^2 / 3); measured 7e-6 off at r = 20
    (texel centres), tolerance 1e-4. Across a wrapping texture's seam it continues on the
    other side; a stroke is filled in to a third of the radius apart."""
    from jaxskin.editor import _brush as brush

    mask = np.zeros((100, 100))
    brush.dab(mask, 50.0, 50.0, 20.0, wrap=False)
    assert mask.sum() == pytest.approx(np.pi * 400 / 3, rel=1e-4)
    assert mask.max() == pytest.approx(1.0, abs=0.01) and mask[50, 72] == 0
    seam = np.zeros((40, 40))
    brush.dab(seam, 1.0, 20.0, 5.0, wrap=True)
    assert seam[20, 38] > 0 and seam[20, 10] == 0
    points = brush.dabs([(0.0, 0.0), (30.0, 0.0)], radius=3.0)
    gaps = np.diff([p[0] for p in points])
    assert len(points) == 31 and gaps.max() <= 1.0 + 1e-9


def test_a_faint_16_bit_map_reads_at_its_full_scale(tmp_path):
    """A painted map saved with every value below 256 (faint paint) is still 16-bit: read
    as value / 65535, not / 255 (`cosmetics.image_map` once judged the scale by the
    largest value; `maps.read_grey` reads every map now)."""
    from jaxskin import maps

    q = np.zeros((4, 4), np.uint16)
    q[1, 2] = 200
    (tmp_path / "faint.png").write_bytes(maps.png16_bytes(q))
    got = maps.read_grey(tmp_path / "faint.png")
    assert got[1, 2] == 200 / 65535 and got.sum() == got[1, 2]
    (tmp_path / "eight.png").write_bytes(maps.png_bytes(q.astype(np.uint8)))
    assert maps.read_grey(tmp_path / "eight.png")[1, 2] == 200 / 255


def test_a_save_keeps_the_scene_files_comments(tmp_path):
    """Saving over a scene keeps its comments and layout where its keys stay (the saved TOML
    once lost every comment): a changed value is replaced in place, a new key added, a
    removed one dropped, and the file reads back equal to the plain writer's."""
    import tomllib

    from jaxskin.editor import keep_comments

    source = ('# my notes on this scene\nname = "mine"\n[mesh]\nfile = "hand"  # the low-res one\n'
              '[material]\n# tuned by eye\nmelanin = 0.3\nblood = 0.4  # a bit pale\n'
              '[camera]\nsize = 64\n')
    (tmp_path / "mine.toml").write_text(source)
    s = Session(str(tmp_path / "mine.toml"), tmp_path / "out")
    s.set({"material.melanin": 0.45, "light.ambient": 0.2})
    s.save("mine")
    text = (tmp_path / "out" / "mine.toml").read_text()
    for comment in ("# my notes on this scene", "# the low-res one", "# tuned by eye"):
        assert comment in text, text
    doc = tomllib.loads(text)
    assert doc["material"] == {"melanin": 0.45, "blood": 0.4} and doc["light"]["ambient"] == 0.2
    assert doc == tomllib.loads(dumps(s.document()))
    # a key removed takes its comment with it
    del doc["material"]["blood"]
    assert "# a bit pale" not in keep_comments(source, doc)
    assert tomllib.loads(keep_comments(source, doc)) == doc
    # an array of tables grown or shrunk (field edits): the tables kept keep their comments
    src = ('[[fields.edit]]  # forehead\nvertex = 1\nd1 = [1.0, 0.0, 0.0]\nd2 = [0.0, 1.0, 0.0]\n'
           '[[fields.edit]]  # cheek\nvertex = 2\nd1 = [1.0, 1.0, 0.0]\nd2 = [-1.0, 1.0, 0.0]\n')
    edits = tomllib.loads(src)
    edits["fields"]["edit"].append({"vertex": 3, "d1": [0.5, 0, 0], "d2": [0, 0.5, 0]})
    grown = keep_comments(src, edits)
    assert "# forehead" in grown and "# cheek" in grown and tomllib.loads(grown) == edits
    edits["fields"]["edit"] = edits["fields"]["edit"][:1]
    shrunk = keep_comments(src, edits)
    assert "# forehead" in shrunk and "# cheek" not in shrunk and tomllib.loads(shrunk) == edits
    # the first edit deleted: the cheek's comment stays on the cheek's table, and a comment
    # goes with its table when the layers are reordered (matched by content, then by name)
    edits["fields"]["edit"] = tomllib.loads(src)["fields"]["edit"][1:]
    first_gone = keep_comments(src, edits)
    assert "# forehead" not in first_gone and "# cheek\nvertex = 2" in first_gone, first_gone
    layers = ('[[layer]]  # the red one\nname = "lips"\nthickness_mm = 0.01\n'
              '[[layer]]  # pale\nname = "cheeks"\nthickness_mm = 0.02\n')
    doc = {"layer": [{"name": "cheeks", "thickness_mm": 0.03}, {"name": "lips",
                                                                "thickness_mm": 0.01}]}
    swapped = keep_comments(layers, doc)
    assert tomllib.loads(swapped) == doc
    assert swapped.index("# pale") < swapped.index('"cheeks"') < swapped.index("# the red"), \
        swapped
    # a document the styled route cannot reproduce falls back to the plain text
    assert keep_comments("not [ toml", {"a": 1}) == dumps({"a": 1})


def test_a_save_elsewhere_rewrites_the_skin_map_images_paths(tmp_path):
    """Saved into another folder, a scene's relative paths are rewritten to still name the
    same files: the skin's map images too (they were left as they were, so the saved
    scene named files that are not there)."""
    from jaxskin.editor import relocate

    doc = {"skin": {"melanin_image": "maps/m.png", "haemoglobin_image": "h.png"},
           "layer": [{"name": "blush", "material": "blush_rose", "image": "b.png"}]}
    relocate(doc, tmp_path / "src", tmp_path / "out")
    assert doc["skin"] == {"melanin_image": "../src/maps/m.png",
                           "haemoglobin_image": "../src/h.png"}
    assert doc["layer"][0]["image"] == "../src/b.png"
    assert doc["layer"][0]["material"] == "blush_rose"  # a shipped name stays a name


def test_a_link_with_paint_says_on_another_editor_that_the_paint_stayed_behind(tmp_path):
    """The paint lives on the editor that made it; a link opened on another one restored
    the rest and dropped the paint without a word. The link now names the painted layers
    and the other editor says why they are bare."""
    (tmp_path / "tiny.toml").write_text(SCENE)
    s = Session(str(tmp_path / "tiny.toml"), tmp_path / "out")
    s.set({"light.ambient": 0.2})
    t = texture.mapped(*_changes._texture_key(s.scene.config))[1]
    s.paint = {"blush": np.ones((t.height, t.width), np.uint16)}
    link = s.query()
    assert link == [["light.ambient", "0.2"], ["painted", "blush"]]
    other = Session(str(tmp_path / "tiny.toml"), tmp_path / "out2")
    refused = other.open(str(tmp_path / "tiny.toml"), link)
    assert other.changes == {"light.ambient": 0.2} and other.paint == {}
    assert refused == [{"key": "painted", "error": "the paint on blush stays on the editor that "
                        "made this link; save the scene there to keep it (its maps are written "
                        "beside it)"}]


def test_saved_paint_is_not_modified_until_painted_again(tmp_path):
    """The title said "(modified)" right after a save of a painted layer: paint counted as a
    change for as long as the session held it. Now only paint since the save does."""
    (tmp_path / "tiny.toml").write_text(SCENE)
    s = Session(str(tmp_path / "tiny.toml"), tmp_path / "out")
    assert s.state()["modified"] is False
    t = texture.mapped(*_changes._texture_key(s.scene.config))[1]
    s.paint = {"blush": np.ones((t.height, t.width), np.uint16)}
    assert s.state()["modified"] is True
    s.save("painted")
    assert s.state()["modified"] is False and s.state()["painted"] == ["blush"]
    s.paint = {"blush": np.zeros((t.height, t.width), np.uint16)}  # a stroke: a new array
    assert s.state()["modified"] is True


def test_a_scene_the_page_uploads_or_opens_may_not_name_files_outside(tmp_path):
    """The page could read any file: upload a scene whose layer image (or mesh) names it,
    open that scene, render (an outside photo would render as the blush).
    Scenes the page uploads or opens are held to the session's folders and the shipped
    data, as /api/set is; the scene the editor was started on keeps the files it names."""
    import imageio.v3 as iio

    from jaxskin.editor import EditorError

    (tmp_path / "private").mkdir()
    photo = tmp_path / "private" / "photo.png"
    iio.imwrite(photo, np.full((8, 8), 200, np.uint8))
    (tmp_path / "scenes").mkdir()
    ellipse = SCENE[SCENE.index("[[layer.ellipse]]"):SCENE.index("[[fields.edit]]")]
    outside = SCENE.replace(ellipse, f'image = "{photo}"\n')
    (tmp_path / "scenes" / "start.toml").write_text(SCENE)
    s = Session(str(tmp_path / "scenes" / "start.toml"), tmp_path / "out")
    for name, text in (("leak.toml", outside),
                       ("mesh.toml", SCENE.replace('file = "face"', 'file = "../private/m.obj"'))):
        if name == "mesh.toml":
            (tmp_path / "private" / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
        with pytest.raises(EditorError) as info:
            s.upload(name, text.encode())
        assert info.value.status == 403 and "outside the folders" in info.value.message, name
        assert not (tmp_path / "out" / name).exists()
        (tmp_path / "scenes" / name).write_text(text)  # put there by other means
        with pytest.raises(EditorError) as info:
            s.open(str(tmp_path / "scenes" / name))
        assert info.value.status == 403, name
    assert s.scene.name == "tiny"  # the scene open before is kept
    # No file outside is looked at: the same 403 whether it exists, is a folder, is missing
    # or is not a JSON (errors said "no such file", "no material file" or "not a JSON
    # material file (Expecting value)", telling the page what is there), for every key
    # that names a file; and a material's bare-name lookup does not climb out of data/.
    layer = SCENE[SCENE.index("[[layer]]"):SCENE.index("[[fields.edit]]")]
    for target in (str(photo), str(tmp_path / "private" / "none.png"), str(tmp_path),
                   "../private/photo.png", "../../../../../etc/passwd"):
        for key, text in (
                ("layer.blush.image", SCENE.replace(ellipse, f'image = "{target}"\n')),
                ("layer.blush.material", SCENE.replace('material = "blush_rose"',
                                                       f'material = "{target}"')),
                ("skin.melanin_image", SCENE.replace(layer, "")
                 + f'[skin]\nmelanin_image = "{target}"\n'),
                ("mesh.file", SCENE.replace('file = "face"', f'file = "{target}"'))):
            with pytest.raises(EditorError) as info:
                s.upload("probe.toml", text.encode())
            assert (info.value.status, info.value.key) == (403, key), (target, key)
            assert info.value.message == (f"probe.toml: {key} names a file outside the "
                                          f"folders this editor may read ({s._roots_text()})")
    s.open("makeup")  # shipped files: allowed
    # what the page wrote is in the last line after a signal ("no file was written" was)
    run = cli.Run()
    run.outputs.append(s)
    assert run.finished() == "no file was written"
    s.upload("ok.toml", SCENE.encode())
    assert run.finished().startswith(f"1 file(s) complete in {tmp_path / 'out'}: ok.toml")
    # the command line's own scene may name what it likes, and the page may reopen it
    (tmp_path / "scenes" / "mine.toml").write_text(outside)
    mine = Session(str(tmp_path / "scenes" / "mine.toml"), tmp_path / "out")
    assert mine.scene.layers[0].image == str(photo)
    mine.open("hand")
    mine.open(str(tmp_path / "scenes" / "mine.toml"))


def test_a_stroke_that_leaves_the_image_paints_what_lies_inside(tmp_path):
    """A drag past the view's edge (the page captures the pointer) sent a point outside the
    image: the request was refused, its in-image dabs unpainted, every later request of the
    stroke refused too, and a refused first request left an empty undo step. Now points
    outside are skipped like points off the mesh."""
    (tmp_path / "tiny.toml").write_text(SCENE)
    s = Session(str(tmp_path / "tiny.toml"), tmp_path / "out")
    config, view = s._view()
    W = view.mask.shape[1] // config.supersample
    y = 32.0  # across the face's middle

    before = np.round(s._layer_map(config, "blush") * 65535)

    def painted():  # texels the strokes raised
        return int(np.count_nonzero(s.paint["blush"] > before)) if "blush" in s.paint else 0

    s.paint_stroke("out", "blush", [[-3.0, y]], 3.0, 1.0)  # begins outside: nothing to paint
    assert painted() == 0
    s.paint_stroke("out", "blush", [[W / 2, y], [W + 40.0, y]], 3.0, 1.0)
    inside = painted()
    assert inside > 0
    s.paint_stroke("out", "blush", [[W / 2, y + 6]], 3.0, 1.0)  # the stroke goes on
    assert painted() > inside
    assert len(s.undo_stack) == 1  # one stroke, one step
    s.undo()
    assert painted() == 0


def test_the_stroke_reports_the_brush_size_it_paints(tmp_path):
    """Where a texel spans several image pixels (a 16² texture seen at 64 px), a brush of
    half a pixel paints a dab of MIN_RADIUS texels: the reply gives that radius in image
    pixels (the page draws its circle so): 5.0 px measured at the face's middle, where a
    texel spans 6.7 px (the uv layout gives the middle more than the face's 100 px / 16
    texels); a brush larger than the texels is reported as it is; one off the mesh none."""
    (tmp_path / "tiny.toml").write_text(SCENE.replace("size = 64\n[wrinkles]",
                                                      "size = 16\n[wrinkles]"))
    s = Session(str(tmp_path / "tiny.toml"), tmp_path / "out")
    config, view = s._view()
    W = view.mask.shape[1] // config.supersample
    small = s.paint_stroke("a", "blush", [[W / 2, 32.0]], 0.5, 1.0)["radius_px"]
    assert 3.0 < small < 8.0, small  # the half-pixel brush was drawn as half a pixel
    assert s.paint_stroke("b", "blush", [[W / 2, 32.0]], 12.0, 1.0)["radius_px"] == 12.0
    assert s.paint_stroke("c", "blush", [[1.0, 1.0]], 3.0, 1.0)["radius_px"] is None


def test_requests_from_other_pages_are_refused(session, folder):
    """A web page on another origin can send a "simple" POST (text/plain, no preflight) to
    the editor on 127.0.0.1 to overwrite the scene it started from, or come in through a
    DNS-rebinding name. Both are refused, and nothing changes; the editor's own
    requests (same Origin, or none, as curl sends) still work."""
    tiny = folder / "scenes" / "tiny.toml"

    async def body(c):
        before = await (await c.get("/api/state")).json()
        text = tiny.read_bytes()
        own = f"http://{c.server.host}:{c.server.port}"
        bad = [({"Origin": "http://evil.example"}, "application/json", 403, "another page"),
               ({"Origin": "null"}, "application/json", 403, "another page"),
               ({"Host": f"evil.example:{c.server.port}"}, "application/json", 403,
                "not this machine's loopback"),
               ({}, "text/plain", 415, "expected Content-Type application/json"),
               ({"Origin": own}, "text/plain", 415, "application/json")]
        for headers, kind, status, words in bad:
            for path, request in (("/api/set", {"changes": {"skin.melanin": 1.7}}),
                                  ("/api/save", {"name": "tiny", "overwrite": True})):
                r = await c.post(path, data=json.dumps(request),
                                 headers={**headers, "Content-Type": kind})
                assert r.status == status and words in (await r.json())["error"], (headers,
                                                                                   kind)
        r = await c.get("/api/state", headers={"Host": "evil.example"})
        assert r.status == 403  # nothing to read through a rebound name either
        after = await (await c.get("/api/state")).json()
        assert after["values"] == before["values"] and tiny.read_bytes() == text
        assert not (folder / "out" / "tiny.toml").exists()
        for headers in ({"Origin": own}, {}, {"Host": f"localhost:{c.server.port}"}):
            r = await c.post("/api/set", json={"changes": {"skin.melanin": 0.5}},
                             headers=headers)
            assert r.status == 200, (headers, await r.text())
        assert (await c.post("/api/undo", headers={"Origin": own})).status == 200
    serve(session, body)


def test_save_names_files_and_far_points(tmp_path):
    """Save as "mine.toml" writes mine.toml, not mine.toml.toml; with the output folder
    the scene's own, Open lists every file once; a paint point at x = 1e300 is refused (a
    segment to it would list 1e300 / spacing dabs)."""
    (tmp_path / "tiny.toml").write_text(SCENE)
    s = Session(str(tmp_path / "tiny.toml"), tmp_path)
    files = s.files()
    assert files["scenes"].count(str(tmp_path / "tiny.toml")) == 1
    assert len(files["materials"]) == len(set(files["materials"]))
    s.save("mine.toml")
    assert (tmp_path / "mine.toml").is_file() and not (tmp_path / "mine.toml.toml").exists()
    with pytest.raises(EditorError, match="far outside the 64x64 image"):
        s.paint_stroke("far", "blush", [[32.0, 32.0], [1e300, 60.0]], 3.0, 1.0)
    assert len(s.undo_stack) == 0  # refused before the stroke's undo step
    from jaxskin.editor import _brush as brush

    assert len(brush.dabs([(0.0, 0.0), (1e12, 0.0)], 3.0)) == brush.MAX_DABS


def test_a_relative_scene_path_with_a_folder_and_a_pick_far_outside(tmp_path, monkeypatch):
    """`jaxskin edit scenes/tiny.toml -o out` must not look for scenes/scenes/tiny.toml or
    out/scenes/tiny.toml: the command line's scene is read from the working directory, as
    `render` reads it. A pick at x = 1e308 is not a 500 (an overflow in floor) but a 400
    naming the image's size."""
    (tmp_path / "scenes").mkdir()
    (tmp_path / "scenes" / "tiny.toml").write_text(SCENE)
    monkeypatch.chdir(tmp_path)
    s = Session("scenes/tiny.toml", "out")
    assert s.path == tmp_path / "scenes" / "tiny.toml"
    for x, y in ((1e308, 1e308), (-1e308, 2.0), (2.0, float(2 ** 70))):
        with pytest.raises(EditorError, match=r"is outside the \d+x\d+ image") as e:
            s.pick(x, y)
        assert e.value.status == 400


def test_a_preview_renders_coarser_spectra_and_looks_the_same(tmp_path, monkeypatch):
    """A preview (while dragging) of a scene on a 10 nm grid renders its spectra at
    `_render.PREVIEW_STEP` (20 nm) and one sample per pixel; the final render (release,
    Save) keeps the scene's grid. The coarser grid changes the picture by little: against a
    preview at 10 nm (tiny face with SSS and a stroke of blush), 8-bit display values differ
    by 0.05 on average and 1 at most (measured)."""
    from jaxskin import maps
    from jaxskin.editor import _render

    (tmp_path / "tiny.toml").write_text(SCENE.replace("step = 20", "step = 10").replace(
        "enabled = false", "enabled = true"))
    s = Session(str(tmp_path / "tiny.toml"), tmp_path / "out")
    s.paint_stroke("a", "blush", [[20.0, 40.0], [44.0, 40.0]], 6.0, 1.0)
    s.render()
    preview = maps.quantize(s.render(preview=True)).astype(float)
    steps = {(k.supersample, k.spectral.step) for k in s._keys.values()}
    assert steps == {(2, 10), (1, 20)} and _render.PREVIEW_STEP == 20
    monkeypatch.setattr(_render, "PREVIEW_STEP", 10)
    d = np.abs(preview - maps.quantize(s.render(preview=True)))
    assert d.mean() <= 0.2 and d.max() <= 2
