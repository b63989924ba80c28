"""Writing scenes as TOML, which the standard library reads but does not write.

`scene_toml(scene)` is the inverse of `load_scene` (what `jaxskin fit-image` writes): a file
that `load_scene` reads back to the same configuration and parameters: every value that
differs from the schema's default, the layers (their regions or images) and the field edits.
Paths are written absolute (meshes, materials other than the shipped ones, BRDF files,
images), except the images given in `images`, which are written as given (file names beside
the new scene file).

`dumps(doc)` writes a scene document (the editor's Save). A scene document holds tables,
strings, booleans, integers, floats (finite), arrays of those and arrays of tables
(`[[layer]]`, `[[fields.edit]]`): what this writes. Floats are written with `repr`, which
reads back as the same float, so a saved scene's values are exactly the editor's.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

from ..io import data_dir
from ._config import Scene
from ._schema import LAYER_SCHEMA, SCHEMA, SKIN_MAPS


def value_text(v) -> str:
    """One TOML value: `0.5`, `true`, `"skin"`, `[0.0, 0.0, 1.0]`, `{vertex = 3, …}`."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise ValueError(f"TOML scene values must be finite, got {v!r}")
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)  # its escapes (\" \\ \n \uXXXX) are TOML's too
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(value_text(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {value_text(x)}" for k, x in v.items()) + "}"
    raise TypeError(f"cannot write {type(v).__name__} as a TOML value")


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() and k.isascii() else json.dumps(k)


def _is_tables(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(doc: dict) -> str:
    """`doc` as TOML text that `tomllib.loads` reads back equal to `doc`."""
    lines: list[str] = []
    _table(doc, [], lines, header=None)
    return "\n".join(lines).strip() + "\n"


def _table(table: dict, path: list[str], lines: list[str], header: str | None) -> None:
    if header is not None:
        lines += ["", header]
    for k, v in table.items():
        if not isinstance(v, dict) and not _is_tables(v):
            lines.append(f"{_key(k)} = {value_text(v)}")
    for k, v in table.items():
        name = ".".join(_key(p) for p in [*path, k])
        if isinstance(v, dict):
            _table(v, [*path, k], lines, f"[{name}]")
        elif _is_tables(v):
            for item in v:
                _table(item, [*path, k], lines, f"[[{name}]]")



def _material(path: str) -> str:
    """A shipped material by its name, any other by its absolute path."""
    p = Path(path)
    return p.stem if p.parent == data_dir() / "materials" else str(p)


def scene_toml(scene: Scene, values: dict | None = None, images: dict | None = None,
               comment: str = "") -> str:
    """The TOML text of `scene`, with `values` (dotted keys: scalars, `light.direction`,
    `layer.NAME.KEY`) replacing the scene's own.

    **Arguments:**

    - `scene`: a loaded scene.
    - `values`: new values by key (floats, or three floats for a vector); their ranges are
      the caller's to respect (`load_scene` checks them when the file is read).
    - `images`: image files by map key: `layer.NAME.map` (the layer's `image`, replacing
      its regions) and the skin maps of `scene.SKIN_MAPS` (`skin.melanin_map` as
      `skin.melanin_image`, …), written as given.
    - `comment`: lines put at the top as TOML comments.

    **Returns:** the text, ending with a newline.
    """
    v = {**scene.values, **(values or {})}
    images = images or {}
    for map_key, (_, image_key) in SKIN_MAPS.items():
        if map_key in images:
            v[image_key] = images[map_key]
    lines = [f"# {line}".rstrip() for line in comment.splitlines()]
    lines.append(f"name = {value_text(v['name'])}")
    section = None
    heads = list(dict.fromkeys(k.split(".")[0] for k in SCHEMA))  # one table per section
    for key, spec in sorted(SCHEMA.items(), key=lambda kv: heads.index(kv[0].split(".")[0])):
        if key == "name" or v[key] is None:
            continue
        value = v[key]
        default = spec.default
        if spec.kind in ("vec2", "vec3"):
            value = [float(c) for c in value]
            default = list(default)
        elif spec.kind is float:
            value = float(value)
        if value == default and key != "material.model":
            continue
        head, name = key.split(".", 1)
        if head != section:
            lines += ["", f"[{head}]"]
            section = head
        lines.append(f"{name} = {value_text(value)}")
    for layer in scene.layers:
        lines += ["", "[[layer]]", f"name = {value_text(layer.name)}",
                  f"material = {value_text(_material(layer.material))}"]
        for k in LAYER_SCHEMA:
            lines.append(f"{k} = {value_text(float(v[f'layer.{layer.name}.{k}']))}")
        image = images.get(f"layer.{layer.name}.map")
        if image is not None or layer.image is not None:
            lines.append(f"image = {value_text(image if image is not None else layer.image)}")
            continue
        for center, radii, angle, feather in layer.ellipses:
            lines += ["[[layer.ellipse]]", f"center = {value_text(list(center))}",
                      f"radii = {value_text(list(radii))}", f"angle = {value_text(float(angle))}",
                      f"feather = {value_text(float(feather))}"]
        for points, vertices, feather in layer.polygons:
            lines.append("[[layer.polygon]]")
            lines.append(f"vertices = {value_text(list(vertices))}" if vertices is not None else
                         f"points = {value_text([list(p) for p in points])}")
            lines.append(f"feather = {value_text(float(feather))}")
    for e in scene.edits:
        lines += ["", "[[fields.edit]]"]
        lines.append(f"vertex = {e.vertex}" if e.vertex is not None else
                     f"at = {value_text(list(e.at))}")
        lines += [f"d1 = {value_text(list(e.d1))}", f"d2 = {value_text(list(e.d2))}",
                  f"weight = {value_text(float(e.weight))}"]
    return "\n".join(lines) + "\n"
