"""Scene documents as the editor changes them: flat `-D`-style keys put into a TOML document,
links' `[key, TOML value]` pairs read, file paths moved to where a scene is saved."""

from __future__ import annotations

import copy
import os
import tomllib
from pathlib import Path

from .. import cosmetics
from ..mesh import BUILTIN as BUILTIN_MESHES
from ..scene import SKIN_MAPS

__all__ = ["EditorError", "keep_aspect", "pair", "put", "relocate"]


class EditorError(Exception):
    """A request the session refuses: `status` (an HTTP 4xx), a one-line `message`, the
    scene `key` it concerns (or None)."""

    def __init__(self, message: str, status: int = 400, key: str | None = None):
        super().__init__(message)
        self.message, self.status, self.key = message, status, key

    def json(self) -> dict:
        """The error as the JSON body of a 4xx answer: `{"error": message, "key": key}`."""
        return {"error": self.message, "key": self.key}


def pair(item) -> tuple:
    """A change from a link: `[key, TOML text]` (the `-D` syntax) or `(key, value)`."""
    if not (isinstance(item, (list, tuple)) and len(item) == 2 and isinstance(item[0], str)):
        raise EditorError(f"expected [key, value] pairs, got {item!r:.100}", 400)
    key, value = item
    if isinstance(value, str) and isinstance(item, list):
        try:
            value = tomllib.loads(f"v = {value}")["v"]
        except tomllib.TOMLDecodeError:
            pass  # a bare word: a string, as -D reads it
    return key, value


def put(doc: dict, key: str, value) -> None:
    """Set a flat key's value in a scene document."""
    if key == "fields.edit":
        fields = doc.setdefault("fields", {})
        if not isinstance(fields, dict):
            raise EditorError("the scene's [fields] is not a table", 400, key)
        fields["edit"] = copy.deepcopy(value)
        return
    parts = key.split(".")
    if parts[0] == "layer":
        name, attr = parts[1], parts[2]
        tables = doc.setdefault("layer", [])
        table = next((t for t in tables if isinstance(t, dict) and t.get("name") == name),
                     None)
        if table is None:
            table = {"name": name}
            tables.append(table)
        table[attr] = value
        return
    if len(parts) == 1:
        doc[key] = value
        return
    section = doc.setdefault(parts[0], {})
    if not isinstance(section, dict):
        raise EditorError(f"the scene's [{parts[0]}] is not a table", 400, key)
    section[parts[1]] = value


def keep_aspect(doc: dict, base: dict) -> None:
    """A `camera.size` changed alone, as `jaxskin render -D camera.size=N` reads it: where
    the scene file (`base`) sets `camera.height`, the height in `doc` is scaled with the
    width (the frame keeps its aspect; the arm at size 64 is 64x20, not a 64x320 strip).
    `EditorError` (key `camera.size`) when that height is over its maximum."""
    from ..io import InputError
    from ..scene import SCHEMA, kept_aspect

    camera = base.get("camera")
    camera = camera if isinstance(camera, dict) else {}
    height = camera.get("height", SCHEMA["camera.height"].default)
    if not height:
        return  # a square frame stays square
    new = doc["camera"]
    try:
        new["height"] = kept_aspect({"camera.height": height, "camera.size": new["size"]},
                                     camera.get("size", SCHEMA["camera.size"].default),
                                     "camera.size")
    except InputError as e:
        raise EditorError(e.message, 400, "camera.size") from None


def relocate(doc: dict, source: Path, output: Path) -> None:
    """Rewrite the document's file paths (relative to `source`, the scene's old folder) to
    be relative to `output` where it is saved (absolute where no relative path exists)."""
    def moved(text: str) -> str:
        p = Path(text) if Path(text).is_absolute() else (source / text).resolve()
        try:
            return Path(os.path.relpath(p, output)).as_posix()
        except ValueError:  # another drive
            return str(p)

    mesh = doc.get("mesh", {})
    if isinstance(mesh.get("file"), str) and mesh["file"] not in BUILTIN_MESHES:
        mesh["file"] = moved(mesh["file"])
    material = doc.get("material", {})
    if isinstance(material.get("brdf"), str) and material["brdf"] != "skin":
        material["brdf"] = moved(material["brdf"])
    skin = doc.get("skin", {})
    for key in [image for _, image in SKIN_MAPS.values()]:  # skin.melanin_image, ...
        name = key.split(".", 1)[1]
        if isinstance(skin.get(name), str):
            skin[name] = moved(skin[name])
    for table in doc.get("layer", []):
        m = table.get("material")
        if isinstance(m, str) and m not in cosmetics.shipped_materials():
            table["material"] = moved(m)
        if isinstance(table.get("image"), str):
            table["image"] = moved(table["image"])
