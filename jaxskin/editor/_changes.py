"""The session's changes: scene keys set from the page, each checked, and undone or redone.

The changes are flat `-D`-style keys (`material.melanin`, `fields.edit`,
`layer.blush.material`, …); each is validated by the scene parser itself
(`scene.parse_scene`), so a bad value gets the schema's own message and leaves the state as
it was.
"""

from __future__ import annotations

import os

import numpy as np

from .. import cosmetics, texture
from ..io import InputError
from ..mesh import BUILTIN as BUILTIN_MESHES
from ..scene import (
    LAYER_SCHEMA,
    SCHEMA,
    SKIN_MAPS,
    SceneConfig,
    check_value,
)
from ._document import EditorError

__all__ = ["HISTORY", "LAYER_SET", "PATH_KEYS", "Changes"]

HISTORY = 50  # undo steps kept
# Every scene key that names a file (the skin's map images too): confined to the session's
# folders, else the page could have the server open any file.
PATH_KEYS = ("mesh.file", "material.brdf", *(image for _, image in SKIN_MAPS.values()))
LAYER_SET = ("material", *LAYER_SCHEMA)  # what the page may set on a layer


class Changes:
    """The `Session`'s changes (its `set`, `undo` and `redo`)."""

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
            raise EditorError(f"expected a scene key, got {key!r:.100}", 400)
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
                # `lexists`: a link there that leads outside is the 403 whether or not
                # its target exists (`exists` follows it, and the answer told which)
                if isinstance(value, str) and not {"/", "\\"} & set(value) and not any(
                        os.path.lexists(r / value) for r in [self.path.parent, *self.roots]):
                    raise EditorError(f"no file {value!r} in {self._roots_text()}; expected "
                                      f"{builtin}, or a file there", 400, key) from None
                raise EditorError(f"{e.message}; or {builtin}", e.status, key) from None
        return value

    def _material(self, value, key):
        if not isinstance(value, str):
            raise EditorError(f"expected a material name or file, got {value!r:.100}", 400, key)
        if value in cosmetics.shipped_materials():
            return value
        path = self.confine(value, key, self.path.parent)
        if not path.is_file():  # then each folder: an upload lands in the output folder
            path = self.confine(value, key)
        if not path.is_file():
            raise EditorError(f"no material file {value!r} (shipped materials: "
                              f"{', '.join(cosmetics.shipped_materials())}; or a calibrated "
                              f"JSON in {self._roots_text()})", 400, key)
        try:
            cosmetics.check_material(path)
        except InputError as e:
            raise EditorError(str(e), 400, key) from None
        return str(path)

    def _record(self, state: tuple | None = None) -> None:
        """An undo step back to `state` (default: now), `(changes, paint)`."""
        self.undo_stack.append(state or (self.changes, self.paint))
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


def _texture_key(config: SceneConfig) -> tuple:
    t = config.texture
    return t.mesh, t.projection, t.size



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

