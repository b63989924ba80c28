"""The editor's bad-input tables for what a careless user or an attacker sends it (issue
37): names in its folders that are links leading outside them (or no regular file), names
too long to be file names, and links (URLs) whose keys did not reach the scene.

Each case checks the answer (status, key, message) and that nothing outside the folders
was read or written. The server's own tests are tests/test_editor.py (its `SCENE`, a small
face with one cosmetic layer, is used here)."""

import asyncio
import os
import threading
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("aiohttp", reason="the editor needs aiohttp (the edit extra)")
from aiohttp.test_utils import TestClient, TestServer  # noqa: E402
from test_editor import SCENE, Server, needs_browser, wait_idle  # noqa: E402
from test_editor import browser as browser  # noqa: E402, F401  (its fixture)

from jaxskin import cli, texture  # noqa: E402
from jaxskin.editor import EditorError, Session, _changes, make_app  # noqa: E402
from jaxskin.io import data_dir  # noqa: E402

MATERIAL = (data_dir() / "materials" / "blush_rose.json").read_bytes()


@pytest.fixture
def place(tmp_path):
    """scenes/tiny.toml, an output folder out/ and a folder private/ outside both, with a
    material and a scene in it (what a link must not tell the page about)."""
    for d in ("scenes", "out", "private"):
        (tmp_path / d).mkdir()
    (tmp_path / "scenes" / "tiny.toml").write_text(SCENE)
    (tmp_path / "private" / "secret.json").write_bytes(MATERIAL)
    (tmp_path / "private" / "secret.toml").write_text(SCENE)
    return tmp_path


def session_in(place, out="out"):
    return Session(str(place / "scenes" / "tiny.toml"), place / out)


def refused(call, status, key="name", words=""):
    with pytest.raises(EditorError) as info:
        call()
    assert (info.value.status, info.value.key) == (status, key), info.value.message
    assert words in info.value.message
    return info.value.message


def snapshot(folder: Path) -> dict:
    """Every entry under `folder` (links not followed): its kind and bytes."""
    out = {}
    for p in sorted(folder.rglob("*")):
        out[str(p)] = ("link", os.readlink(p)) if p.is_symlink() else (
            ("dir",) if p.is_dir() else ("file", p.read_bytes()))
    return out


def painted(s, layer="blush"):
    """`layer` painted (a map set as a stroke sets it, without the render)."""
    t = texture.mapped(*_changes._texture_key(s.scene.config))[1]
    s.paint = {**s.paint, layer: np.full((t.height, t.width), 30000, np.uint16)}


# --- Item 1: names in the folders that lead outside them --------------------------------

LEAD_OUTSIDE = "is a link that leads outside the folders this editor may read"

# out/<name> -> a target outside the folders: each is refused (403) by upload and Save
# before it is looked at, whatever the target is and whatever the body holds.
LINKS = {
    "same.json": "private/secret.json",  # the body equals it: the issue's 200
    "other.json": "private/secret.json",  # the body differs: the issue's 409
    "dangling.json": "private/none.json",  # where nothing is yet (a write would land there?)
    "folder.json": "private",
    "scene.toml": "private/secret.toml",
    "dangling.toml": "private/none.toml",
    "chain.toml": "out/scene.toml",  # a link to a link that leads outside
    "etc.toml": "/etc/passwd",
}


def test_links_in_the_output_folder_that_lead_outside_are_refused_before_any_read(place):
    s = session_in(place)
    out = place / "out"
    for name, target in LINKS.items():
        os.symlink(target if target.startswith("/") else place / target, out / name)
    before = snapshot(place / "private")
    for name in LINKS:
        for body in (MATERIAL, SCENE.encode(), b"other"):
            message = refused(lambda n=name, b=body: s.upload(n, b), 403, words=LEAD_OUTSIDE)
            assert "private" not in message and "passwd" not in message  # the target unsaid
        if name.endswith(".toml"):
            for overwrite in (False, True):
                refused(lambda n=name, o=overwrite: s.save(n[:-5], o), 403, words=LEAD_OUTSIDE)
    # a painted map's name that leads outside: nothing of the save is written, the scene
    # either
    painted(s)
    os.symlink(place / "private" / "map.png", out / "look_blush.png")
    assert refused(lambda: s.save("look", True), 403, words=LEAD_OUTSIDE).startswith(
        "look_blush.png in ")
    assert not (out / "look.toml").exists()
    assert snapshot(place / "private") == before
    assert all((out / name).is_symlink() for name in LINKS)  # not replaced either
    # a link that stays inside the folders is a file of theirs: compared, as a file there is
    os.symlink(place / "scenes" / "tiny.toml", out / "inside.toml")
    assert s.upload("inside.toml", SCENE.encode()) == str(out / "inside.toml")
    refused(lambda: s.upload("inside.toml", b"x = 1\n"), 409, words="with other contents")


def test_the_issues_upload_through_a_link_over_http(place):
    """The issue's case as it came: POST /api/upload?name=link.json answered 200 when the
    body equalled the file the link leads to, 409 otherwise."""
    os.symlink(place / "private" / "secret.json", place / "out" / "link.json")
    s = session_in(place)

    async def main():
        async with TestClient(TestServer(make_app(s, log=lambda line: None))) as c:
            answers = []
            for body in (MATERIAL, b"{}"):
                r = await c.post("/api/upload?name=link.json", data=body)
                answers.append((r.status, (await r.json())["key"]))
            return answers
    assert asyncio.run(main()) == [(403, "name"), (403, "name")]


def test_an_output_folder_that_became_a_link_outside_is_not_written_through(place):
    """The output folder is made when first needed; one that is a link by then (to a
    folder outside) is not written into."""
    s = session_in(place, "later")
    os.symlink(place / "private", place / "later")
    before = snapshot(place / "private")
    refused(lambda: s.upload("new.json", MATERIAL), 403, words=LEAD_OUTSIDE)
    refused(lambda: s.save("new"), 403, words=LEAD_OUTSIDE)
    assert snapshot(place / "private") == before


def test_what_a_link_leads_to_is_not_told_by_a_mesh_files_error(place):
    """`mesh.file = "m.obj"` with scenes/m.obj a link outside: the answer was the 403 when
    its target existed and "no file 'm.obj'" when not, telling the page which."""
    (place / "private" / "m.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    os.symlink(place / "private" / "m.obj", place / "scenes" / "m.obj")
    os.symlink(place / "private" / "none.obj", place / "scenes" / "n.obj")
    s = session_in(place)
    answers = {refused(lambda v=v: s.set({"mesh.file": v}), 403, "mesh.file",
                       "outside the folders").replace(v, "V") for v in ("m.obj", "n.obj")}
    assert len(answers) == 1, answers


def test_no_regular_file_in_the_folders_is_a_409_not_a_500_or_a_hang(place, capsys):
    """A folder, a named pipe, a link loop or a hard link where an upload or Save would
    compare or replace a file: a folder was replaced (IsADirectoryError, a 500), a pipe
    read (the editor's one worker waited forever), a link loop resolved (RuntimeError, a
    500); a hard link may be another name of a file outside, so its contents are not
    compared."""
    out = place / "out"
    s = session_in(place)
    (out / "folder.json").mkdir()
    (out / "folder.toml").mkdir()
    os.mkfifo(out / "pipe.json")
    os.symlink("loop.toml", out / "loop.toml")
    os.symlink("missing.json", out / "broken.json")  # dangling, inside
    os.link(place / "private" / "secret.json", out / "hard.json")
    done = []

    def uploads():
        for name in ("folder.json", "pipe.json", "loop.toml", "broken.json"):
            refused(lambda n=name: s.upload(n, MATERIAL), 409, words="not a regular file")
        refused(lambda: s.upload("hard.json", MATERIAL), 409, words="a file with other names")
        for name in ("folder", "loop"):
            for overwrite in (False, True):
                refused(lambda n=name, o=overwrite: s.save(n, o), 409,
                        words="not a regular file")
        done.append(True)
    worker = threading.Thread(target=uploads, daemon=True)
    worker.start()
    worker.join(60)
    assert done, "an upload or a save waited on a named pipe (or failed: see above)"
    # open and the list of files: a loop is no scene (404), links outside are not listed
    refused(lambda: s.open("loop.toml"), 404, None, "no scene file")
    os.symlink(place / "private" / "secret.toml", out / "away.toml")
    os.symlink(place / "private" / "secret.json", out / "away.json")
    files = s.files()
    assert not [f for f in files["scenes"] + files["materials"] if "away" in f]
    assert str(place / "scenes" / "tiny.toml") in files["scenes"]
    # the command line's scene a link loop: exit 2, one line ("edit failed unexpectedly
    # (RuntimeError: Symlink loop ...)" was)
    assert cli.main(["edit", str(out / "loop.toml"), "-o", str(out), "--no-browser"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("jaxskin: error: no scene file") and "\n" not in err, err


# --- Item 3: names too long to be file names ---------------------------------------------

LONG = "a" * 250


def test_a_long_layer_name_is_refused_when_the_scene_is_read(place):
    """A 250-character `[[layer]] name`, painted, then Save: an OSError (File name too
    long), a 500. The name is now limited where the scene is read: the editor's open and
    upload answer 400 naming it, `jaxskin render` exits 2 with one line."""
    text = SCENE.replace('name = "blush"', f'name = "{LONG}"')
    (place / "scenes" / "long.toml").write_text(text)
    s = session_in(place)
    for call in (lambda: s.open(str(place / "scenes" / "long.toml")),
                 lambda: s.upload("long.toml", text.encode())):
        message = refused(call, 400, "layer[0].name", "a layer's name is at most 64 characters")
        assert "got 250" in message and len(message) < 400
    assert not (place / "out" / "long.toml").exists()
    # 64 characters is a name; 65 is not
    for n, ok in ((65, False), (64, True)):
        name = "b" * n
        change = {f"layer.{name}.material": "blush_rose"}
        if ok:
            s.set(change)
            assert s.scene.layers[-1].name == name
        else:  # a layer the page adds (a link's key, the Add layer field)
            refused(lambda c=change: s.set(c), 400, "layer[1].name", "at most 64 characters")


def test_a_long_layer_name_on_the_command_line_exits_2_with_one_line(place, capsys):
    text = SCENE.replace('name = "blush"', f'name = "{LONG}"')
    (place / "scenes" / "long.toml").write_text(text)
    tiny = str(place / "scenes" / "tiny.toml")
    for argv in (["render", str(place / "scenes" / "long.toml"), "-o", str(place / "o")],
                 ["edit", str(place / "scenes" / "long.toml"), "-o", str(place / "o"),
                  "--no-browser"],
                 # a layer that -D adds (the editor's -D is a link's keys)
                 ["edit", tiny, "-o", str(place / "o"), "--no-browser", "-D",
                  f"layer.{'c' * 65}.material=blush_rose"]):
        assert cli.main(argv) == 2, argv
        err = capsys.readouterr().err.strip()
        assert err.count("\n") == 0 and err.startswith("jaxskin: error:"), err
        assert "].name" in err and "at most 64 characters" in err, err
    assert not (place / "o").exists()


@pytest.mark.parametrize("name, layer, words", [
    # 190 + "_" + 64 + ".png": 259 bytes, over the 255 of a file system's file name
    ("n" * 190, "b" * 64, f"layer '{'b' * 64}''s painted map would be saved as"),
    # 200 + "_" + 40 + ".png": 245 bytes, and the temporary file beside it 14 more
    ("n" * 200, "b" * 40, f"layer '{'b' * 40}''s painted map would be saved as"),
    # 240 bytes is a save name; with ".toml" and the temporary file's 14, over 255
    ("é" * 120, None, "the scene would be saved as"),
    # and what fits is saved: 200 characters, 205 with ".toml", 210 with "_blush.png"
    ("n" * 200, "blush", None),
])
def test_a_save_whose_files_would_not_be_file_names_is_a_400(place, name, layer, words):
    s = session_in(place)
    if layer is not None:
        if layer != "blush":
            s.set({f"layer.{layer}.material": "blush_rose"})
        painted(s, layer)
    if words is None:
        s.save(name)
        assert sorted(p.name for p in (place / "out").iterdir()) == [
            f"{name}.toml", f"{name}_{layer}.png"]
        return
    message = refused(lambda: s.save(name), 400, "name", words)
    assert "shorter name" in message and len(message) < 400
    assert not list((place / "out").iterdir())


# --- Item 10: a link's keys without scene= ---------------------------------------------

def test_a_links_keys_apply_to_the_scene_open_now_and_each_refused_one_is_named(place):
    """`/?material.melanin=0.9` (no `scene=`) opened the server's scene unchanged and said
    nothing. The page now sends such keys to /api/apply: applied to the scene open now
    (its changes and paint kept, one undo step), each refused key named."""
    s = session_in(place)
    s.set({"wrinkles.k_bump": 0.1})
    painted(s)
    undo = len(s.undo_stack)

    async def main():
        async with TestClient(TestServer(make_app(s, log=lambda line: None))) as c:
            r = await c.post("/api/apply", json={"changes": [
                ["skin.melanin", "0.9"], ["materal.melanin", "0.5"],
                ["layer.nope.thickness_mm", "0.1"], ["camera.rotate", "[0.0, 10.0, 0.0]"],
                ["painted", "blush"]]})
            state = await r.json()
            assert r.status == 200, state
            assert state["values"]["skin.melanin"] == 0.9
            assert state["values"]["camera.rotate"] == [0.0, 10.0, 0.0]
            assert state["values"]["wrinkles.k_bump"] == 0.1 and state["painted"] == ["blush"]
            assert [r["key"] for r in state["refused"]] == [
                "materal.melanin", "layer.nope.thickness_mm", "painted"]
            assert state["refused"][0]["error"] == ("unknown table [materal]; did you mean "
                                                    "'material.melanin'?")
            assert "no layer named 'nope'" in state["refused"][1]["error"]
            assert state["undo"] == undo + 1  # one step for the link
            state = await (await c.post("/api/undo")).json()
            assert state["values"]["skin.melanin"] == 0.0 and state["painted"] == ["blush"]
            # nothing applied: no undo step
            r = await c.post("/api/apply", json={"changes": [["bogus", "1"]]})
            assert (await r.json())["undo"] == undo
            # bad bodies, too many keys (for a link with scene= too): 400, nothing changed
            for path, body in (("/api/apply", {"changes": "skin.melanin=1"}),
                               ("/api/apply", {}),
                               ("/api/apply", {"changes": [["skin.melanin", "1"]] * 1001}),
                               ("/api/open", {"scene": s.source,
                                              "changes": [["skin.melanin", "1"]] * 1001})):
                r = await c.post(path, json=body)
                assert r.status == 400 and "error" in await r.json(), (path, body)
            state = await (await c.get("/api/state")).json()
            assert state["values"]["skin.melanin"] == 0.0 and state["painted"] == ["blush"]
    asyncio.run(main())


@needs_browser
def test_a_link_without_scene_changes_the_scene_in_the_page(place, browser):
    """The issue's link in the browser: keys without `scene=` reach the server's scene
    (when this browser last showed that scene too: its remembered state once replaced
    the link), a key that is no scene's is named in the status line."""
    server = Server(session_in(place))
    d = browser
    status = "return document.getElementById('message').textContent"
    try:
        d.get(f"http://127.0.0.1:{server.port}/?skin.melanin=0.9&bogus=1")
        v = wait_idle(d)
        assert d.execute_script("return S.values['skin.melanin']") == 0.9
        assert d.execute_script(status).startswith("not applied: bogus: unknown key"), \
            d.execute_script(status)
        assert "scene=" in d.current_url and "skin.melanin=0.9" in d.current_url
        d.get(f"http://127.0.0.1:{server.port}/?light.ambient=0.5")
        v = wait_idle(d)
        assert d.execute_script("return [S.values['light.ambient'], S.values['skin.melanin']]"
                                ) == [0.5, 0.9]
        assert d.execute_script(status) == f"applied to {place / 'scenes' / 'tiny.toml'}: " \
                                           "light.ambient"
        d.get(f"http://127.0.0.1:{server.port}/?scene=&camera.exposure=1")  # scene= empty
        wait_idle(d, v)
        assert d.execute_script("return [S.values['camera.exposure'], S.undo]") == [1.0, 3]
        assert not [e for e in d.get_log("browser") if e["level"] == "SEVERE"]
    finally:
        server.close()


def test_a_long_key_or_value_is_not_echoed_whole(place):
    """A 100,000-character key (or a material given as a long list) came back whole in the
    error, the line the page shows."""
    s = session_in(place)
    for change, key in (({"k" * 100_000: 1}, None),
                        ({"layer.blush.material": list(range(30_000))}, "layer.blush.material")):
        message = refused(lambda c=change: s.set(c), 400, key)
        assert len(message) < 300, len(message)
