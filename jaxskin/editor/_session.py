"""The editor's session: a scene document, the changes made to it, painted maps, renders.

One `Session` per server. It holds the scene file's TOML document (`base`), the changes the
page made as flat `-D`-style keys (`changes`: `material.melanin`, `fields.edit`,
`layer.blush.material`, …) and the painted thickness maps (`paint`: 16-bit, texture space).
Every change is validated by the scene parser itself (`scene.parse_scene`), so a bad value
gets the schema's own message and leaves the state as it was. Its jobs are in the classes
it is made of: `Changes` (`_changes`), `Rendering` (`_render`), `Painting` (`_paint`) and
`Saving` (`_save`).
"""

from __future__ import annotations

import copy
import dataclasses
import os
import tomllib
from pathlib import Path

import numpy as np

from .. import cosmetics
from ..io import InputError, data_dir
from ..mesh import BUILTIN as BUILTIN_MESHES
from ..scene import (
    BUILTIN_SCENES,
    LAYER_SCHEMA,
    SCHEMA,
    LayerSpec,
    Scene,
    SceneConfig,
    builtin_scenes,
    parse_scene,
    toml_error,
    toml_text,
)
from ._changes import PATH_KEYS, Changes
from ._document import EditorError, keep_aspect, pair, put
from ._paint import Painting, Stroke
from ._render import Rendering
from ._save import Saving

__all__ = ["Session", "real", "schema"]

PAINTED = "painted"  # in a link: the layers painted where it was made (the maps stay there)
LINK_KEYS = 1000  # the most changes a link may hold (the schema has ~50 keys, 6 per layer)


class Session(Changes, Rendering, Painting, Saving):
    """The state of one editor: see the module's docstring.

    **Arguments:**

    - `scene`: a built-in scene name or a TOML file.
    - `output`: the folder Save writes to (created when first needed).
    """

    def __init__(self, scene: str = "hand", output=".", roots=()):
        self.output = real(output)
        first = Path(str(scene))
        self.roots = [self.output]
        if str(scene) not in BUILTIN_SCENES:
            self.roots.append(real(first).parent)
        self.roots += [real(r) for r in roots]
        self._keys: dict = {}  # signature → the configuration compiled for it
        self._cover_cache: tuple | None = None
        self._side: tuple | None = None  # (configuration, its hidden-side warning)
        self._prepared: list[SceneConfig] = []  # configurations prepared, newest first
        self.version = 0  # bumped on every change of what the view shows
        self.timings: dict[str, float] = {}
        self._trusted: set[Path] = set()  # the files the command line's scene names
        self.written: list[Path] = []  # every file Save and uploads wrote (for the last line)
        # the command line's scene from the working directory, as `render` reads it
        # (`edit dir/s.toml -o out` reads dir/s.toml, not dir/dir/s.toml or out/dir/s.toml)
        self.open(str(scene) if str(scene) in BUILTIN_SCENES else str(real(first)), {})
        self._trusted = set(_scene_files(self.scene).values())

    # --- opening and the document --------------------------------------------------------

    def open(self, scene: str, changes: dict | None = None) -> list[dict]:
        """Load a scene (a built-in name or a file inside the session's folders) and apply
        `changes` (from a link); returns the changes refused, each `{key, error}`."""
        items = _items(changes)
        path = self._scene_path(scene)
        try:
            text = toml_text(path.read_bytes(), path)
            base = tomllib.loads(text)
            # a scene the page names (not the command line's) may name files only in the
            # session's folders and the shipped data
            scene_obj = parse_scene(base, path, allow=(
                lambda k, f: self._allow(k, f, path.name)) if hasattr(self, "scene") else None)
        except OSError as e:
            raise EditorError(f"{path}: cannot read ({e.__class__.__name__})", 400) from None
        except tomllib.TOMLDecodeError as e:
            raise EditorError(str(toml_error(e, path)), 400) from None
        except InputError as e:
            raise EditorError(str(e), 400, e.key) from None
        self._check(scene_obj)
        self.source = scene if scene in BUILTIN_SCENES else str(path)
        self.path, self.base = path, base
        self.text = text  # its comments, kept by a save
        self.changes: dict = {}
        self.paint: dict[str, np.ndarray] = {}
        self.saved_paint: dict[str, np.ndarray] = {}  # the maps as the scene file has them
        self.scene = scene_obj
        self.undo_stack: list = []
        self.redo_stack: list = []
        self._stroke: Stroke | None = None
        self.saved_as: str | None = None
        self.version += 1
        return self._each(items)

    def apply(self, changes) -> list[dict]:
        """Apply a link's `changes` (`[[key, TOML value], ...]`, or `{key: value}`) to the
        scene open now, its changes and paint kept (a link without `scene=`): each change on
        its own, all that apply as one undo step. Returns the changes refused, each
        `{key, error}`, for the page to name."""
        items = _items(changes)
        before = (self.changes, self.paint)
        refused = self._each(items)
        if self.changes is not before[0] or self.paint is not before[1]:
            self._record(before)
        return refused

    def _each(self, items: list) -> list[dict]:
        """Apply a link's changes (`_items`) one by one, unrecorded; the ones refused."""
        refused = []
        for item in items:
            try:
                key, value = pair(item)
                if key == PAINTED:  # a link made where paint was: it cannot bring it here
                    refused.append({"key": PAINTED, "error": (
                        f"the paint on {value} stays on the editor that made this link; save "
                        "the scene there to keep it (its maps are written beside it)")})
                    continue
                self.set({key: value}, record=False)
            except EditorError as e:
                refused.append({"key": e.key or str(item)[:100], "error": e.message})
        return refused

    def _scene_path(self, scene: str) -> Path:
        if scene in BUILTIN_SCENES:
            return builtin_scenes()[scene]
        path = self.confine(scene, "scene")
        if path.suffix != ".toml" or not path.is_file():
            raise EditorError(f"no scene file {scene!r} (a .toml file in "
                              f"{self._roots_text()}, or a built-in scene: "
                              f"{', '.join(BUILTIN_SCENES)})", 404)
        return path

    def _allow(self, key: str, file: Path, name: str) -> None:
        """`parse_scene`'s `allow` for a scene the page opens or uploads: `EditorError`
        (403) when it names a file (mesh, BRDF, skin or layer image, material) outside the
        session's folders and the shipped data, raised before that file is looked at, so
        the page can neither read a file outside by naming it in a scene nor learn whether
        one exists. The files of the scene the editor was started on are allowed."""
        allowed = [*self.roots, data_dir().resolve()]
        if file in self._trusted or any(file.is_relative_to(r) for r in allowed):
            return
        raise EditorError(f"{name}: {key} names a file outside the folders "
                          f"this editor may read ({self._roots_text()})", 403, key)

    def _roots_text(self) -> str:
        return " or ".join(dict.fromkeys(str(r) for r in self.roots))  # each folder once

    def confine(self, text: str, what: str, base: Path | None = None) -> Path:
        """`text` as a path inside one of the session's folders (the scene's, the output
        folder): relative to `base` (default: each folder in turn), links resolved; an
        `EditorError` (403, its key `what`) for anything outside them."""
        if not isinstance(text, str) or not text or "\0" in text or len(text) > 1000:
            raise EditorError(f"expected a file name, got {text!r}", 400, what)
        p = Path(text)
        candidates = [p] if p.is_absolute() else [
            (b / p) for b in ([base] if base is not None else self.roots)]
        for c in candidates:
            r = real(c)
            if any(r.is_relative_to(root) for root in self.roots) and (
                    r.exists() or c is candidates[-1]):
                return r
        raise EditorError(f"{text!r} is outside the folders this editor may read "
                          f"({self._roots_text()})", 403, what)

    def inside(self, path: Path) -> bool:
        """Whether `path`, its links resolved, lies in one of the session's folders."""
        r = real(path)
        return any(r.is_relative_to(root) for root in self.roots)

    def output_file(self, name: str) -> Path:
        """`<output>/<name>`, which Save and uploads look at (is it there, what it holds)
        and replace: an `EditorError` (403) before anything is looked at when it is a link
        that leads outside the session's folders (or the output folder became one), since
        `exists()` and `read_bytes()` follow links and the answers would tell the page
        whether a file outside exists and what it holds."""
        target = self.output / name
        if not self.inside(target):
            raise EditorError(f"{name} in {self.output} is a link that leads outside the "
                              f"folders this editor may read ({self._roots_text()}); remove "
                              "it or choose another name", 403, "name")
        return target

    def document(self, changes: dict | None = None) -> dict:
        """The scene's TOML document with `changes` (default: the session's) applied, as
        `jaxskin render -D` applies them (a `camera.size` alone keeps the file's aspect)."""
        changes = self.changes if changes is None else changes
        doc = copy.deepcopy(self.base)
        for key, value in changes.items():
            put(doc, key, value)
        if "camera.size" in changes and "camera.height" not in changes:
            keep_aspect(doc, self.base)  # as -D camera.size: the file's frame kept
        return doc

    def _build(self, changes: dict, paint: dict) -> Scene:
        """The scene of a document and paint, validated; `EditorError` with the schema's
        message otherwise."""
        try:
            scene = parse_scene(self.document(changes), self.path)
        except InputError as e:
            raise EditorError(e.message, 400, e.key) from None
        if paint:
            scene = dataclasses.replace(scene, layers=tuple(
                LayerSpec(spec.name, spec.material, None) if spec.name in paint else spec
                for spec in scene.layers))
        return scene

    def _check(self, scene: Scene) -> None:
        """What the CLI checks before a render (memory, mesh, vertices, materials, images)."""
        from ..checks import check_scene

        try:
            check_scene(scene, 1)
        except InputError as e:
            raise EditorError(str(e), 400, e.key) from None
        except RecursionError:
            raise EditorError("nested too deeply to read", 400) from None

    # --- what the page shows -------------------------------------------------------------

    def files(self) -> dict:
        """Scenes and materials the page can open: built-in ones and files in the folders."""
        scenes, materials = list(BUILTIN_SCENES), cosmetics.shipped_materials()
        for root in dict.fromkeys(self.roots):  # once if they are one
            if root.is_dir():  # not links that lead outside (`open` refuses them)
                scenes += sorted(str(p) for p in root.glob("*.toml") if self.inside(p))[:200]
                materials += sorted(str(p) for p in root.glob("*.json")
                                    if self.inside(p))[:200]
        return {"scenes": scenes, "materials": materials}

    def state(self) -> dict:
        """Everything the page draws its panels from (JSON)."""
        sc = self.scene
        values = {k: _jsonable(v) for k, v in sc.values.items()}
        config = sc.config
        layers = [{"name": s.name, "material": _material_name(s.material),
                   "painted": s.name in self.paint} for s in sc.layers]
        return {"source": self.source, "path": str(self.path), "name": sc.name,
                "values": values, "changes": {k: _jsonable(v) for k, v in self.changes.items()},
                "query": self.query(), "edits": [dataclasses.asdict(e) for e in sc.edits],
                "layers": layers, "version": self.version,
                "image": [config.image, config.image_height or config.image],
                "painted": sorted(self.paint), "modified": self.modified(),
                "undo": len(self.undo_stack),
                "redo": len(self.redo_stack), "output": str(self.output),
                "saved_as": self.saved_as, "warnings": self.warnings(), "schema": schema()}

    def warnings(self) -> list[str]:
        """The render command's warnings about what the page shows (`picture_warnings`: a
        skin map that changes nothing, a view from the side of a planar map, a layer thick as
        a mask); the side's share measured once a configuration."""
        from ..checks import hidden_side, picture_warnings

        config = self.scene.config
        if self._side is None or self._side[0] != config:
            self._side = (config, hidden_side(self.scene))
        return picture_warnings(self.scene, self._side[1])

    def modified(self) -> bool:
        """Whether the page differs from its scene file: a change, or paint not saved."""
        return bool(self.changes) or any(self.paint.get(k) is not self.saved_paint.get(k)
                                         for k in {*self.paint, *self.saved_paint})

    def query(self) -> list[list[str]]:
        """The changes as `[key, value]` pairs with TOML values, the `-D` syntax (the page's
        URL holds them)."""
        from ..scene import value_text

        painted = [[PAINTED, ",".join(sorted(self.paint))]] if self.paint else []
        return [[k, value_text(v)] for k, v in self.changes.items()] + painted


def _items(changes) -> list:
    """A link's changes, `{key: value}` or `[[key, TOML value], ...]`, as a list of items;
    an `EditorError` (400) for anything else or too many: each is a parse of the scene on
    the one worker (3.2 ms on the tests' 64² face), so the 50,000 keys a 1 MiB body holds
    would keep the page waiting for about 160 s."""
    if changes is None:
        return []
    if not isinstance(changes, (dict, list)):
        raise EditorError("expected changes as {key: value} or [[key, TOML value], ...]", 400)
    if len(changes) > LINK_KEYS:
        raise EditorError(f"a link sets at most {LINK_KEYS} keys, got {len(changes)}", 400)
    return list(changes.items()) if isinstance(changes, dict) else changes


def real(path) -> Path:
    """`path` with every link resolved, as `os.path.realpath` does: a link loop gives a
    path (that is no file), not the `RuntimeError` of `Path.resolve` (a 500)."""
    return Path(os.path.realpath(path))


def _scene_files(scene: Scene) -> dict:
    """`{key: resolved path}` of every file a parsed scene names (built-in meshes and the
    preset BRDF are none)."""
    v = scene.values
    out = {}
    if v["mesh.file"] not in BUILTIN_MESHES:
        out["mesh.file"] = v["mesh.file"]
    if v["material.brdf"] != "skin":
        out["material.brdf"] = v["material.brdf"]
    for key in PATH_KEYS[2:]:
        if v.get(key):
            out[key] = v[key]
    for layer in scene.layers:
        out[f"layer.{layer.name}.material"] = layer.material
        if layer.image:
            out[f"layer.{layer.name}.image"] = layer.image
    return {k: real(f) for k, f in out.items()}


def schema() -> dict:
    """The scene schema for the page: kind, default, range, choices, differentiable."""
    def one(spec):
        kind = spec.kind if isinstance(spec.kind, str) else spec.kind.__name__
        return {"kind": kind, "default": _jsonable(spec.default), "lo": spec.lo, "hi": spec.hi,
                "choices": list(spec.choices) if spec.choices else None, "param": spec.param}

    return {"keys": {k: one(v) for k, v in SCHEMA.items()},
            "layer": {k: one(v) for k, v in LAYER_SCHEMA.items()}}




def _material_name(path: str) -> str:
    p = Path(path)
    shipped = data_dir() / "materials" / f"{p.stem}.json"
    return p.stem if p == shipped else path


def _jsonable(v):
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    return v
