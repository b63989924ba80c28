"""The editor's session: a scene document, the changes made to it, painted maps, renders.

One `Session` per server. It holds the scene file's TOML document (`base`), the changes the
page made as flat `-D`-style keys (`changes`: `material.melanin`, `fields.edit`,
`layer.blush.material`, …) and the painted thickness maps (`paint`: 16-bit, texture space).
Every change is validated by the scene parser itself (`scene.parse_scene`), so a bad value
gets the schema's own message and leaves the state as it was.

Rendering calls the renderer the CLI calls (`render.render_prepared` with the arrays of
`render.prepare`), with three things that only change arrays, never the traced program:

- a field edit changes the furrows: `texture.furrows` of the new configuration replaces
  `h0` (the view and every other array are the configuration's without the edit);
- a painted layer's thickness map replaces its row of `cover`, exactly as `prepare` would
  read it back from the 16-bit PNG that Save writes;
- the jit cache key (the static configuration) is the first configuration seen that
  differs only in those (edits, layer materials and maps, the shadow's direction), so none
  of them retraces; `render` of the saved scene compiles the same program and gives the
  same bytes (tests/test_editor.py).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import time
import tomllib
from pathlib import Path

import numpy as np

from .. import cosmetics, maps, render, texture
from ..io import InputError, atomic_write, data_dir
from ..mesh import BUILTIN as BUILTIN_MESHES
from ..outputs import check_name
from ..scene import (
    BUILTIN_SCENES,
    LAYER_SCHEMA,
    SCHEMA,
    SKIN_MAPS,
    LayerSpec,
    Scene,
    SceneConfig,
    builtin_scenes,
    check_value,
    dumps,
    parse_scene,
    toml_text,
)
from ..scene import toml_error as _toml_error
from . import brush
from .document import EditorError, keep_aspect, pair, put, relocate

__all__ = ["EditorError", "Session"]

HISTORY = 50  # undo steps kept
PAINTED = "painted"  # in a link: the layers painted where it was made (the maps stay there)
# Every scene key that names a file: confined to the session's folders (the skin's map
# images once were not: the page could have the server open any file).
PATH_KEYS = ("mesh.file", "material.brdf", *(image for _, image in SKIN_MAPS.values()))
LAYER_SET = ("material", *LAYER_SCHEMA)  # what the page may set on a layer


@dataclasses.dataclass
class _Stroke:
    """A brush stroke in progress: its layer, the map before it and the union of its dabs."""

    id: str
    layer: str
    before: np.ndarray  # float64 (H, W) in [0, 1]
    mask: np.ndarray  # float64 (H, W) in [0, 1]
    last: tuple | None = None  # the stroke's last point so far (image pixels)


class Session:
    """The state of one editor: see the module's docstring.

    **Arguments:**

    - `scene`: a built-in scene name or a TOML file.
    - `output`: the folder Save writes to (created when first needed).
    """

    def __init__(self, scene: str = "hand", output=".", roots=()):
        self.output = Path(output).resolve()
        first = Path(str(scene))
        self.roots = [self.output]
        if str(scene) not in BUILTIN_SCENES:
            self.roots.append(first.resolve().parent)
        self.roots += [Path(r).resolve() for r in roots]
        self._keys: dict = {}  # signature → the configuration compiled for it
        self._cover_cache: tuple | None = None
        self._side: tuple | None = None  # (configuration, its hidden-side warning)
        self._prepared: list[SceneConfig] = []  # configurations prepared, newest first
        self.version = 0  # bumped on every change of what the view shows
        self.timings: dict[str, float] = {}
        self._trusted: set[Path] = set()  # the files the command line's scene names
        self.written: list[Path] = []  # every file Save and uploads wrote (for the last line)
        # the command line's scene from the working directory, as `render` reads it
        # (`edit dir/s.toml -o out` looked for dir/dir/s.toml and out/dir/s.toml, a trial)
        self.open(str(scene) if str(scene) in BUILTIN_SCENES else str(first.resolve()), {})
        self._trusted = set(_scene_files(self.scene).values())

    # --- opening and the document --------------------------------------------------------

    def open(self, scene: str, changes: dict | None = None) -> list[dict]:
        """Load a scene (a built-in name or a file inside the session's folders) and apply
        `changes` (from a link); returns the changes refused, each `{key, error}`."""
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
            raise EditorError(str(_toml_error(e, path)), 400) from None
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
        self._stroke: _Stroke | None = None
        self.saved_as: str | None = None
        self.version += 1
        refused = []
        items = changes.items() if isinstance(changes, dict) else changes or []
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
            r = c.resolve()
            if any(r.is_relative_to(root) for root in self.roots) and (
                    r.exists() or c is candidates[-1]):
                return r
        raise EditorError(f"{text!r} is outside the folders this editor may read "
                          f"({self._roots_text()})", 403, what)

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

    # --- changes -------------------------------------------------------------------------

    def set(self, values: dict, record: bool = True) -> None:
        """Apply `{key: value}` changes (value None: back to the file's value), all or none."""
        if not isinstance(values, dict) or not values:
            raise EditorError("expected an object of scene keys and values", 400)
        changes = dict(self.changes)
        names = [layer.name for layer in self.scene.layers]
        adding = [k.split(".")[1] for k, v in values.items() if isinstance(k, str)
                  and k.startswith("layer.") and k.endswith(".material") and v is not None]
        for key, value in values.items():
            if value is None:
                changes.pop(key, None)
                continue
            changes[key] = self._checked(key, value, [*names, *adding])
        paint = self.paint
        scene = self._build(changes, paint)
        added = [s.name for s in scene.layers if s.name not in names
                 and s.name not in paint and not (s.image or s.ellipses or s.polygons)]
        if added:  # a layer added here starts bare, to be painted (else it covers everything)
            t = texture.mapped(*_texture_key(scene.config))[1]
            paint = {**paint, **{n: np.zeros((t.height, t.width), np.uint16) for n in added}}
            scene = self._build(changes, paint)
        if scene.config != self.scene.config:
            self._check(scene)
        if record:
            self._record()
        self.changes, self.scene, self.paint = changes, scene, paint
        self.version += 1

    def _checked(self, key, value, layer_names):
        """A change's key and value checked as far as they can be alone (the rest when the
        document is parsed): known keys, paths confined, materials and meshes found."""
        if not isinstance(key, str) or len(key) > 200:
            raise EditorError(f"expected a scene key, got {key!r}", 400)
        if key == "fields.edit":
            if not isinstance(value, list) or len(value) > 1000:
                raise EditorError("fields.edit: expected a list of edits (at most 1000)", 400,
                                  key)
            return value
        parts = key.split(".")
        if len(parts) == 3 and parts[0] == "layer":
            name, attr = parts[1], parts[2]
            if not name.isidentifier():
                raise EditorError(f"a layer's name must be letters, digits and _, got "
                                  f"{name!r}", 400, key)
            if attr not in LAYER_SET:
                raise EditorError(f"a layer's value to set must be one of "
                                  f"{', '.join(LAYER_SET)}", 400, key)
            if attr == "material":
                return self._material(value, key)
            if name not in layer_names:
                raise EditorError(f"no layer named {name!r} (add it by choosing its "
                                  "material first)", 400, key)
            return _scalar(value, key, layer_names)
        if key not in SCHEMA or key == "name":
            try:
                check_value(key, value, "editor", layer_names)
            except InputError as e:
                message = e.message
                if message.startswith("unknown key; valid keys:"):  # 46 keys: too long a line
                    message = ("unknown key, and none near it (the panel shows every key; "
                               "their meaning: python -m pydoc jaxskin.scene)")
                raise EditorError(message, 400, key) from None
            raise EditorError(f"{key!r} cannot be set here", 400, key)
        value = _scalar(value, key, layer_names)
        if key in PATH_KEYS and not (key == "mesh.file" and value in BUILTIN_MESHES) and not (
                key == "material.brdf" and value == "skin"):
            try:
                value = str(self.confine(value, key, self.path.parent))
            except EditorError as e:
                if key not in ("mesh.file", "material.brdf"):  # an image: no built-in ones
                    raise
                builtin = ("a built-in mesh: " + ", ".join(BUILTIN_MESHES)
                           if key == "mesh.file" else 'the built-in "skin"')
                if isinstance(value, str) and not {"/", "\\"} & set(value) and not any(
                        (r / value).exists() for r in [self.path.parent, *self.roots]):
                    raise EditorError(f"no file {value!r} in {self._roots_text()}; expected "
                                      f"{builtin}, or a file there", 400, key) from None
                raise EditorError(f"{e.message}; or {builtin}", e.status, key) from None
        return value

    def _material(self, value, key):
        if not isinstance(value, str):
            raise EditorError(f"expected a material name or file, got {value!r}", 400, key)
        if value in cosmetics.shipped_materials():
            return value
        path = self.confine(value, key, self.path.parent)
        if not path.is_file():  # then each folder: an upload lands in the output folder
            path = self.confine(value, key)  # (a trial: 'm.json' was not found there)
        if not path.is_file():
            raise EditorError(f"no material file {value!r} (shipped materials: "
                              f"{', '.join(cosmetics.shipped_materials())}; or a calibrated "
                              f"JSON in {self._roots_text()})", 400, key)
        try:
            cosmetics.check_material(path)
        except InputError as e:
            raise EditorError(str(e), 400, key) from None
        return str(path)

    def _record(self) -> None:
        self.undo_stack.append((self.changes, self.paint))
        del self.undo_stack[:-HISTORY]
        self.redo_stack.clear()

    def undo(self) -> bool:
        """Go back one change; False when there is none to undo."""
        return self._step(self.undo_stack, self.redo_stack)

    def redo(self) -> bool:
        """Redo the last undone change; False when there is none."""
        return self._step(self.redo_stack, self.undo_stack)

    def _step(self, source: list, target: list) -> bool:
        if not source:
            return False
        changes, paint = source.pop()
        target.append((self.changes, self.paint))
        self.changes, self.paint = changes, paint
        self.scene = self._build(changes, paint)
        self._stroke = None
        self.version += 1
        return True

    # --- rendering -----------------------------------------------------------------------

    def _key(self, config: SceneConfig) -> SceneConfig:
        """The configuration to compile `config` as: the first seen that differs only in
        what `arrays` passes in (edits, layer materials and maps, the shadow's direction,
        the camera's turn, zoom, centre and field of view): a turn or a zoom renders in the
        program compiled already (0.5 s a new one on the 64² hand, and a few memory
        mappings each, which a long session would run out of)."""
        sig = dataclasses.replace(
            config, texture=dataclasses.replace(config.texture, edits=()),
            shadow=None if config.shadow is None else (0.0, 0.0, 1.0),
            rotate=(0.0, 0.0, 0.0), zoom=1.0, center=(0.0, 0.0), fov=0.0)
        if config.spectral is not None:
            sig = dataclasses.replace(sig, spectral=dataclasses.replace(
                config.spectral, layers=tuple(LayerSpec(s.name, "", None)
                                              for s in config.spectral.layers)))
        return self._keys.setdefault(sig, config)

    def arrays(self, config: SceneConfig) -> dict:
        """`render.prepare(config).arrays`, computed for the configuration without its
        field edits where one with them is at hand, the edits' furrows and painted maps put
        in."""
        prepared = render.prepare(self._prepared_config(config))
        # Without the view's transpose table (reverse mode only; the editor takes no
        # gradients): its row count changes with every turn or zoom, and so would the
        # arrays' shapes and the compiled program.
        arrays = {k: v for k, v in prepared.arrays.items() if k not in render.VIEWS}
        if config.needs_furrows:
            arrays["h0"] = texture.furrows(config.texture)[0]
        if self.paint and config.spectral is not None:
            arrays["cover"] = self._cover(config, arrays)
        return arrays

    def _prepared_config(self, config: SceneConfig) -> SceneConfig:
        """A configuration equal to `config` but for what `arrays` puts in (field edits,
        painted layers' maps) whose preparation is cached already (else `config`): an edit
        then costs a furrow run and a stroke nothing, not a new view, shadow map or blur."""
        def normal(c: SceneConfig) -> SceneConfig:
            c = dataclasses.replace(c, texture=dataclasses.replace(c.texture, edits=()))
            if c.spectral is None or not self.paint:
                return c
            return dataclasses.replace(c, spectral=dataclasses.replace(c.spectral, layers=tuple(
                LayerSpec(s.name, s.material, None) if s.name in self.paint else s
                for s in c.spectral.layers)))

        for other in self._prepared:
            if normal(other) == normal(config):
                return other
        self._prepared = [config, *self._prepared[:5]]
        return config

    def _cover(self, config: SceneConfig, arrays: dict):
        import jax.numpy as jnp

        names = [s.name for s in config.spectral.layers]
        key = (id(arrays["cover"]), tuple((n, id(self.paint.get(n))) for n in names))
        if self._cover_cache is not None and self._cover_cache[0] == key:
            return self._cover_cache[1]
        texels = np.asarray(arrays["texels"])
        cover = np.array(arrays["cover"])
        for i, name in enumerate(names):
            if name in self.paint:  # as maps.read_grey reads the saved 16-bit PNG
                q = self.paint[name]
                cover[i] = np.clip(q.astype(np.float64) / 65535.0, 0.0, 1.0).reshape(-1)[
                    texels].astype(np.float32)
        out = jnp.asarray(cover, jnp.float32)
        self._cover_cache = (key, out)
        return out

    def render(self, preview: bool = False) -> np.ndarray:
        """The view `(H, W, 3)` display values, as `jaxskin render` makes it (`preview`:
        one sample per pixel, for drags)."""
        config = self.scene.config
        if preview and config.supersample > 1:
            config = dataclasses.replace(config, supersample=1)
        t0 = time.perf_counter()
        arrays = self.arrays(config)
        image = render.render_prepared(self._key(config), self.scene.params, arrays)
        image = np.asarray(image)
        self.timings["render_s"] = time.perf_counter() - t0
        return image

    def png(self, preview: bool = False) -> bytes:
        """The view as the PNG `jaxskin render` writes (8-bit)."""
        return maps.image_bytes(self.render(preview))

    def image_file(self, preview: bool = False) -> tuple[bytes, str]:
        """The view as the page gets it, `(bytes, MIME type)`: the PNG `jaxskin render`
        writes; a preview as an uncompressed BMP of the same 8-bit samples (2 ms to encode
        at 512², where the PNG takes 30-60 ms on this CPU)."""
        if not preview:
            return self.png(), "image/png"
        import imageio.v3 as iio

        image = maps.quantize(self.render(preview))
        return iio.imwrite("<bytes>", image, extension=".bmp"), "image/bmp"

    # --- the view: picking, arrows, painting ---------------------------------------------

    def _view(self):
        config = self.scene.config
        return config, render.prepare(self._prepared_config(config)).view

    def _sample(self, view, k: int, x, y):
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool)
                   and math.isfinite(v) for v in (x, y)):
            raise EditorError("expected pixel coordinates x, y (numbers)", 400)
        H, W = view.mask.shape
        if not (0 <= y * k < H and 0 <= x * k < W):  # before floor: 1e308 * k is inf (a 500)
            raise EditorError(f"pixel ({x}, {y}) is outside the {W // k}x{H // k} image", 400)
        return int(math.floor(y * k)), int(math.floor(x * k))

    def pick(self, x, y) -> dict:
        """The mesh vertex nearest to image pixel `(x, y)` (the triangle the view's raster
        sees there, its corner of largest barycentric), with the screen's axes in the
        mesh's frame (for turning a drag into a direction)."""
        config, view = self._view()
        k = config.supersample
        i, j = self._sample(view, k, x, y)
        tri = int(view.raster.tri[i, j])
        R = view.R
        axes = {"right": (R.T @ [1.0, 0.0, 0.0]).tolist(),
                "down": (R.T @ [0.0, -1.0, 0.0]).tolist()}
        if tri < 0:
            return {"hit": False, **axes}
        mesh = texture.setup(config.texture).mesh
        vertex = int(mesh.faces[tri][int(np.argmax(view.raster.bary[i, j]))])
        s = texture.setup(config.texture)
        return {"hit": True, "vertex": vertex, "position": mesh.vertices[vertex].tolist(),
                "d1": s.d1[vertex].tolist(), "d2": s.d2[vertex].tolist(),
                "normal": mesh.normals[vertex].tolist(),
                "screen": (view.xy[vertex] / k).tolist(), **axes}

    def fields(self, step: int = 24) -> dict:
        """The direction fields seen in the view, for the arrows: every `step` image pixels
        on the mesh, `[x, y, d1x, d1y, d2x, d2y]` (screen directions, image pixels per unit
        of |d|), and each edit's vertex on the screen."""
        config, view = self._view()
        k = config.supersample
        s = texture.setup(config.texture)
        H, W = view.mask.shape
        ys = (np.arange(step // 2, H // k, step) * k + k // 2)
        xs = (np.arange(step // 2, W // k, step) * k + k // 2)
        ii, jj = np.meshgrid(ys, xs, indexing="ij")
        tri = view.raster.tri[ii, jj]
        on = tri >= 0
        ii, jj, tri = ii[on], jj[on], tri[on]
        bary = view.raster.bary[ii, jj].astype(np.float64)
        corners = s.mesh.faces[tri]
        out = [(ii + 0.5) / k, (jj + 0.5) / k]
        for d in (s.d1, s.d2):
            v = np.einsum("nk,nkc->nc", bary, d[corners]) @ view.R.T
            out += [v[:, 0], -v[:, 1]]
        rows = np.stack([out[1], out[0], *out[2:]], axis=1)
        edits = [{"index": n, "vertex": e.vertex, "screen": (view.xy[e.vertex] / k).tolist()}
                 for n, e in enumerate(s.edits)]
        return {"arrows": np.round(rows, 2).tolist(), "edits": edits}

    def paint_stroke(self, stroke: str, layer: str, points, radius: float, strength: float,
                     erase: bool = False) -> dict:
        """Paint (or erase) `layer`'s thickness map along `points` (image pixels), a soft
        brush of `radius` image pixels: each point's texel from the view's texture lookup,
        the radius in texels from the lookup's local scale. Repeated calls with the same
        `stroke` id extend one stroke (one undo step; dabs do not pile up within it).
        Returns `{"dabs": n, "radius_px": r}`: r is the last dab's radius in image pixels
        (None if no dab landed on the mesh), above `radius` where the texels are larger
        than the brush (a close view of a coarse texture), so the page can draw the brush
        circle as large as what it paints."""
        config, view = self._view()
        if config.spectral is None or layer not in [s.name for s in config.spectral.layers]:
            names = [s.name for s in config.spectral.layers] if config.spectral else []
            none = "none; material.model must be spectral or biophysical"
            raise EditorError(f"no cosmetic layer {layer!r} to paint (this scene's layers: "
                              f"{', '.join(names) or none})", 400, "layer")
        if not (isinstance(points, list) and 0 < len(points) <= 10000 and all(
                isinstance(p, list) and len(p) == 2 and all(
                    isinstance(c, (int, float)) and not isinstance(c, bool)
                    and math.isfinite(c) for c in p) for p in points)):
            raise EditorError("points: expected a list of [x, y] pixel positions (1-10000)", 400)
        for name, v, lo, hi in (("radius", radius, 0.5, 500.0), ("strength", strength, 0, 1)):
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not lo <= v <= hi:
                raise EditorError(f"{name}: expected a number in [{lo:g}, {hi:g}], got {v!r}")
        H, W = (n // config.supersample for n in view.mask.shape)
        far = [p for p in points if not (-W <= p[0] <= 2 * W and -H <= p[1] <= 2 * H)]
        if far:  # a drag may leave the image, not by more than its size (1e300 was a 200)
            raise EditorError(f"points: {far[0]} is far outside the {W}x{H} image (at most "
                              "one image size beyond its edges)", 400)
        k = config.supersample
        s = texture.setup(config.texture)
        Ht, Wt = s.tmap.height, s.tmap.width
        if self._stroke is None or self._stroke.id != stroke or self._stroke.layer != layer:
            before = self._layer_map(config, layer)
            self._record()
            self._stroke = _Stroke(str(stroke), layer, before, np.zeros((Ht, Wt)))
        mask = self._stroke.mask
        points = [tuple(map(float, p)) for p in points]
        last = self._stroke.last  # the stroke goes on from where its last request ended
        dabs = brush.dabs(points, radius) if last is None else brush.dabs(
            [last, *points], radius)[1:]
        self._stroke.last = points[-1]
        H, W = view.mask.shape
        shown = None
        for x, y in dabs:
            i, j = math.floor(y * k), math.floor(x * k)
            if not (0 <= i < H and 0 <= j < W and view.shaded[i, j]):
                continue  # off the image (a drag that left the view: the page captures the
                # pointer) or off the mesh; a stroke may go out and come back
            t = view.tex[i, j].astype(np.float64)
            scale = brush.texels_per_pixel(view, i, j, k)
            r = max(radius * scale, brush.MIN_RADIUS)
            brush.dab(mask, t[0], t[1], r, s.tmap.wrap_x)
            shown = r / scale
        target = 0.0 if erase else 1.0
        before = self._stroke.before
        value = before + (target - before) * float(strength) * mask
        first = layer not in self.paint
        self.paint = {**self.paint, layer: np.round(np.clip(value, 0, 1) * 65535).astype(
            np.uint16)}
        if first:  # the layer's regions or image give way to its map
            self.scene = self._build(self.changes, self.paint)
        self.version += 1
        return {"dabs": len(dabs), "radius_px": shown}

    def _layer_map(self, config: SceneConfig, layer: str) -> np.ndarray:
        """A layer's thickness map `(H, W)` in [0, 1] as the render has it now."""
        if layer in self.paint:
            return self.paint[layer].astype(np.float64) / 65535.0
        arrays = self.arrays(config)
        names = [s.name for s in config.spectral.layers]
        s = texture.setup(config.texture)
        out = np.zeros(s.tmap.height * s.tmap.width)
        out[np.asarray(arrays["texels"])] = np.asarray(arrays["cover"][names.index(layer)])
        return out.reshape(s.tmap.height, s.tmap.width)

    # --- saving --------------------------------------------------------------------------

    def save(self, name: str, overwrite: bool = False) -> list[str]:
        """Write `<output>/<name>.toml` and each painted map as `<name>_<layer>.png` (16-bit
        grey) beside it: a scene `jaxskin render` renders to the image shown. The session
        then edits the saved file."""
        if isinstance(name, str) and name.lower().endswith(".toml"):
            name = name[:-5]  # "my_makeup.toml" wrote my_makeup.toml.toml
        try:
            check_name(name, "save")
        except InputError as e:
            raise EditorError(e.message, 400, "name") from None
        toml_path = self.output / f"{name}.toml"
        layers = [spec.name for spec in self.scene.layers]
        pngs = {layer: self.output / f"{name}_{layer}.png" for layer in self.paint
                if layer in layers}
        for p in [toml_path, *pngs.values()]:
            if p.exists() and not overwrite:
                raise EditorError(f"{p.name} exists in {self.output}; save with overwrite to "
                                  "replace it", 409, "name")
            if p.exists() and p.resolve() == self.path.resolve() and self.source in \
                    BUILTIN_SCENES:
                raise EditorError("cannot overwrite a built-in scene", 403, "name")
        doc = self.document()
        doc["name"] = name
        relocate(doc, self.path.parent, self.output)
        for table in doc.get("layer", []):
            if table.get("name") in pngs:
                for k in ("image", "ellipse", "polygon"):
                    table.pop(k, None)
                table["image"] = pngs[table["name"]].name
        text = keep_comments(self.text, doc)
        self.output.mkdir(parents=True, exist_ok=True)
        for layer, p in pngs.items():
            with atomic_write(p, "wb") as fh:
                fh.write(maps.png16_bytes(self.paint[layer]))
            self.written.append(p)
        with atomic_write(toml_path, "w") as fh:
            fh.write(text)
        self.written.append(toml_path)
        paint, version = self.paint, self.version
        self.open(str(toml_path), {})
        self.paint, self.saved_as = paint, str(toml_path)
        self.saved_paint = dict(paint)  # strokes replace arrays: `is` tells what changed
        self.scene = self._build({}, paint)
        self.version = version + 1
        return [str(toml_path), *(str(p) for p in pngs.values())]

    def upload(self, name: str, data: bytes) -> str:
        """Keep a file the page uploads (a scene `.toml`, or a cosmetic material `.json` from
        `jaxskin calibrate`) in the output folder, checked first: the way to bring in a
        file from outside the session's folders. Returns its path."""
        try:
            check_name(name, "upload")
        except InputError as e:
            raise EditorError(e.message, 400, "name") from None
        suffix = Path(name).suffix
        if suffix not in (".toml", ".json"):
            raise EditorError("expected a scene (.toml) or a material (.json)", 400, "name")
        target = self.output / name
        if target.exists():
            if target.read_bytes() == data:
                return str(target)
            raise EditorError(f"{name} exists in {self.output} with other contents; rename "
                              "the file to upload it", 409, "name")
        import tempfile

        with tempfile.TemporaryDirectory() as tmp:
            probe = Path(tmp) / name
            probe.write_bytes(data)
            try:
                if suffix == ".json":
                    cosmetics.check_material(probe)
                else:
                    doc = tomllib.loads(toml_text(data, name))
                    scene = parse_scene(doc, target, allow=lambda k, f: self._allow(k, f, name))
                    check_name(scene.name, target)  # as render checks it (a trial: a
                    # name = "../../x" was uploaded, and refused only by a later render)
            except InputError as e:
                raise EditorError(f"{name}: {e.message}", 400, e.key) from None
            except (UnicodeDecodeError, tomllib.TOMLDecodeError) as e:
                raise EditorError(f"{name}: not a TOML scene ({e})", 400) from None
        self.output.mkdir(parents=True, exist_ok=True)
        with atomic_write(target, "wb") as fh:
            fh.write(data)
        self.written.append(target)
        return str(target)

    # --- what the page shows -------------------------------------------------------------

    def files(self) -> dict:
        """Scenes and materials the page can open: built-in ones and files in the folders."""
        scenes, materials = list(BUILTIN_SCENES), cosmetics.shipped_materials()
        for root in dict.fromkeys(r.resolve() for r in self.roots):  # once if they are one
            if root.is_dir():
                scenes += sorted(str(p) for p in root.glob("*.toml"))[:200]
                materials += sorted(str(p) for p in root.glob("*.json"))[:200]
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
    return {k: Path(f).resolve() for k, f in out.items()}


def _texture_key(config: SceneConfig) -> tuple:
    t = config.texture
    return t.mesh, t.projection, t.size


def schema() -> dict:
    """The scene schema for the page: kind, default, range, choices, differentiable."""
    def one(spec):
        kind = spec.kind if isinstance(spec.kind, str) else spec.kind.__name__
        return {"kind": kind, "default": _jsonable(spec.default), "lo": spec.lo, "hi": spec.hi,
                "choices": list(spec.choices) if spec.choices else None, "param": spec.param}

    return {"keys": {k: one(v) for k, v in SCHEMA.items()},
            "layer": {k: one(v) for k, v in LAYER_SCHEMA.items()}}


def _scalar(value, key, layer_names):
    """A JSON value for `key` as TOML would give it (lists for vectors), checked by the
    schema: `EditorError` with its message."""
    if isinstance(value, (dict,)):
        raise EditorError(f"expected a value, got an object for {key}", 400, key)
    try:
        check_value(key, value, "editor", layer_names)
    except InputError as e:
        raise EditorError(e.message, 400, key) from None
    return value


def _material_name(path: str) -> str:
    p = Path(path)
    shipped = data_dir() / "materials" / f"{p.stem}.json"
    return p.stem if p == shipped else path


def _jsonable(v):
    if isinstance(v, tuple):
        return [_jsonable(x) for x in v]
    return v


def keep_comments(source: str, doc: dict) -> str:
    """`doc` as TOML text, written over the `source` text it was edited from so that the
    source's comments and layout stay where its keys stay (tomlkit, the `edit` extra):
    changed values are replaced, new keys added at the end of their table, removed ones
    dropped. The result must read back equal to `doc`, as `dumps(doc)` does; when it does
    not (or tomlkit is missing) it is `dumps(doc)`, with no comments."""
    plain = dumps(doc)
    try:
        import tomlkit

        styled = tomlkit.parse(source)
        _sync(styled, doc)
        text = tomlkit.dumps(styled)
        if tomllib.loads(text) == tomllib.loads(plain):
            return text
    except Exception:  # any surprise in the styled route: the plain text is always right
        pass
    return plain


def _match_tables(have, value: list) -> None:
    def plain(h):
        return h.unwrap() if hasattr(h, "unwrap") else h

    free = list(range(len(have)))
    match: list = [None] * len(value)
    tests = [lambda h, v: plain(h) == v,
             lambda h, v: "name" in v and plain(h).get("name") == v["name"]]
    for same in tests:
        for i, v in enumerate(value):
            j = next((j for j in free if match[i] is None and same(have[j], v)), None)
            if j is not None:
                match[i] = j
                free.remove(j)
    if len(have) == len(value):
        for i in range(len(value)):
            if match[i] is None and i in free:
                match[i] = i
                free.remove(i)
    kept = list(have.body) if hasattr(have, "body") else list(have)
    while len(have):  # emptied and refilled in place: the array's layout stays
        del have[-1]
    for i, v in enumerate(value):
        if match[i] is None:
            have.append(v)
        else:
            _sync(kept[match[i]], v)
            have.append(kept[match[i]])


def _sync(table, want: dict) -> None:
    """Make the tomlkit `table` equal to `want` in place, touching only what differs."""
    for key in [k for k in table if k not in want]:
        del table[key]
    for key, value in want.items():
        have = table.get(key)
        if isinstance(value, dict) and isinstance(have, dict):
            _sync(have, value)
        elif (isinstance(value, list) and value and all(isinstance(v, dict) for v in value)
              and isinstance(have, list) and have and all(isinstance(h, dict) for h in have)):
            # an array of tables (field edits, layers): each wanted table is matched to a
            # source table, which keeps its comments, by equal content, then by equal
            # `name` (layers), then by position when no table was added or removed;
            # unmatched ones are new, without comments (a deleted edit's comment must not
            # move onto the next one)
            _match_tables(have, value)
        elif have is None or have != value or type(have.unwrap() if hasattr(have, "unwrap")
                                                 else have) is not type(value):
            table[key] = value
