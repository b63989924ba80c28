"""The scene's arrays of tables: `[[fields.edit]]` and `[[layer]]` with its regions
(`[[layer.ellipse]]`, `[[layer.polygon]]`)."""

from __future__ import annotations

import difflib
from pathlib import Path

from .. import cosmetics
from ..io import InputError, real_path
from ..texture import EditSpec
from ._config import LayerSpec
from ._overrides import check_value, number, numbers, vector
from ._schema import EDIT_KEYS, ELLIPSE_KEYS, LAYER_KEYS, LAYER_SCHEMA, POLYGON_KEYS

# A layer's name is part of file names (the editor's `<name>_<layer>.png`, fit-image's
# `<name>_layer.<layer>.map.png`), each checked when written; kept short, it leaves the
# scene's name most of the 255 bytes a file name may take.
MAX_LAYER_NAME = 64


def parse_edit(i, e, path) -> EditSpec:
    """The `i`th [[fields.edit]] table `e`, checked, as an `EditSpec`."""
    where = f"fields.edit[{i}]"
    if not isinstance(e, dict):
        raise InputError("expected a table with at (or vertex), d1, d2, weight", path, key=where)
    e = {k: v for k, v in e.items() if v is not None}  # JSON's null (the editor's state)
    _known(e, EDIT_KEYS, path, where)
    if ("at" in e) == ("vertex" in e):
        raise InputError("give exactly one of 'at' (a point) or 'vertex' (an index)", path,
                         key=where)
    vertex = e.get("vertex")
    if vertex is not None and (not isinstance(vertex, int) or isinstance(vertex, bool)
                               or vertex < 0):
        raise InputError(f"expected a vertex index >= 0, got {vertex!r}", path,
                         key=f"{where}.vertex")
    for k in ("d1", "d2"):
        if k not in e:
            raise InputError(f"missing '{k}'", path, key=where)
    weight = e.get("weight", 1.0)
    if isinstance(weight, bool) or not isinstance(weight, (int, float)) or not (
            0 <= weight <= 10):
        raise InputError(f"must be in [0, 10], got {weight!r}", path, key=f"{where}.weight")
    at = vector(e["at"], f"{where}.at", path) if "at" in e else None
    return EditSpec(at, vertex, vector(e["d1"], f"{where}.d1", path, 2.0),
                    vector(e["d2"], f"{where}.d2", path, 2.0), float(weight))


def parse_layer(i, e, path, values, materials=None, allow=lambda key, file: None) -> LayerSpec:
    """One [[layer]] table: its static spec; its parameters go into `values`. `materials`:
    `material_overrides`, which replace the table's material (a path taken from the
    working directory, as any path given with -D)."""
    name = _layer_name(i, e, path)
    where = f"layer.{name}"
    for k, spec in LAYER_SCHEMA.items():
        values[f"{where}.{k}"] = check_value(f"{where}.{k}", e.get(k, spec.default), path, (name,))
    material, source, base = e.get("material"), path, path.parent
    if name in (materials or {}):
        (material, source), base = materials[name], Path.cwd()
    material = _material_file(material, source, base, where, allow)
    image = _layer_image(e.get("image"), path, where, allow)
    ellipses = _ellipses(e.get("ellipse", []), path, where)
    polygons = _polygons(e.get("polygon", []), path, where)
    if image is not None and (ellipses or polygons):
        raise InputError("give an image or regions (ellipse, polygon), not both", path,
                         key=where)
    return LayerSpec(name, material, image, tuple(ellipses), tuple(polygons))


def _layer_name(i, e, path) -> str:
    """The name of the `i`th [[layer]] table `e`, once the table and its keys are checked."""
    where = f"layer[{i}]"
    if not isinstance(e, dict):
        raise InputError("expected a table with name, material, thickness_mm, ...", path,
                         key=where)
    _known(e, LAYER_KEYS, path, where)
    name = e.get("name")
    if not isinstance(name, str) or not name.isidentifier():
        got = "none (add name = \"...\")" if name is None else repr(name)
        raise InputError(f"expected a name (letters, digits, _), got {got}", path,
                         key=f"{where}.name")
    if len(name) > MAX_LAYER_NAME:
        raise InputError(f"a layer's name is at most {MAX_LAYER_NAME} characters (it is part "
                         f"of the names of the map files written for it), got {len(name)}: "
                         f"{name[:24]!r}...", path, key=f"{where}.name")
    return name


def _material_file(material, source, base: Path, where: str, allow) -> str:
    """A layer's `material` (a shipped one's name, or a JSON file taken from `base`) as the
    absolute path of a readable material file that covers the render grid; errors name
    `source` (the scene file or the -D item)."""
    if not isinstance(material, str) or not material:
        raise InputError("expected a material: a shipped one's name or a JSON file written "
                         "by jaxskin calibrate", source, key=f"{where}.material")
    file = cosmetics.material_path(material, base)
    allow(f"{where}.material", real_path(file))
    if file.exists() and not file.is_file():  # /dev/zero: not "no material file"
        raise InputError(f"not a regular file: {file} (expected a material JSON written by "
                         "jaxskin calibrate)", source, key=f"{where}.material")
    if not file.is_file():
        shipped = cosmetics.shipped_materials()
        near = difflib.get_close_matches(material, shipped, n=1, cutoff=0.75)
        hint = f"did you mean '{near[0]}'? " if near else ""
        raise InputError(f"no material file {file} ({hint}shipped materials: "
                         f"{', '.join(shipped)})", source, key=f"{where}.material")
    cosmetics.check_material(file)  # readable and covering the render grid, before any work
    return str(file)


def _layer_image(image, path, where: str, allow) -> str | None:
    """A layer's greyscale `image` (taken from the scene file's folder) as an absolute path,
    or None."""
    if image is None:
        return None
    if not isinstance(image, str):
        raise InputError(f"expected a greyscale image file, got {image!r}", path,
                         key=f"{where}.image")
    allow(f"{where}.image", real_path(path.parent / image))
    if not (path.parent / image).is_file():
        raise InputError(f"no such file {real_path(path.parent / image)} (expected a "
                         "greyscale image file, taken from the scene file's folder)", path,
                         key=f"{where}.image")
    return str(real_path(path.parent / image))


def _ellipses(tables, path, where: str) -> list:
    """A layer's [[layer.ellipse]] `tables` as `(center, radii, angle, feather)` tuples."""
    ellipses = []
    for j, r in enumerate(_tables(tables, path, f"{where}.ellipse")):
        w = f"{where}.ellipse[{j}]"
        _known(r, ELLIPSE_KEYS, path, w)
        center = numbers(r.get("center"), 2, path, f"{w}.center")
        radii = numbers(r.get("radii"), 2, path, f"{w}.radii", positive=True)
        feather = number(r.get("feather", 0.0), path, f"{w}.feather", lo=0.0)
        reach = max(radii) + feather
        _on_texture([(center[0] - reach, center[1] - reach),
                     (center[0] + reach, center[1] + reach)], path, w)
        ellipses.append((center, radii, number(r.get("angle", 0.0), path, f"{w}.angle"),
                         feather))
    return ellipses


def _polygons(tables, path, where: str) -> list:
    """A layer's [[layer.polygon]] `tables` as `(points, vertices, feather)` tuples, one of
    points (uv) or vertices (mesh indices) set."""
    polygons = []
    for j, r in enumerate(_tables(tables, path, f"{where}.polygon")):
        w = f"{where}.polygon[{j}]"
        _known(r, POLYGON_KEYS, path, w)
        if ("points" in r) == ("vertices" in r):
            raise InputError("give exactly one of 'points' ([[u, v], ...]) or 'vertices' "
                             "(mesh vertex indices)", path, key=w)
        points = vertices = None
        if "points" in r:
            pts = r["points"]
            if not isinstance(pts, list) or len(pts) < 3:
                raise InputError("expected at least three [u, v] points", path,
                                 key=f"{w}.points")
            points = tuple(numbers(q, 2, path, f"{w}.points") for q in pts)
            reach = number(r.get("feather", 0.0), path, f"{w}.feather", lo=0.0)
            _on_texture([(min(q[0] for q in points) - reach, min(q[1] for q in points) - reach),
                         (max(q[0] for q in points) + reach, max(q[1] for q in points) + reach)],
                        path, w)
        else:
            vs = r["vertices"]
            if not (isinstance(vs, list) and len(vs) >= 3 and all(
                    isinstance(v, int) and not isinstance(v, bool) and v >= 0 for v in vs)):
                raise InputError("expected at least three vertex indices >= 0", path,
                                 key=f"{w}.vertices")
            vertices = tuple(vs)
        polygons.append((points, vertices,
                         number(r.get("feather", 0.0), path, f"{w}.feather", lo=0.0)))
    return polygons


def _on_texture(box, path, where) -> None:
    """`InputError` when a region's bounding box `((u0, v0), (u1, v1))`, feather included,
    lies wholly outside the texture (u and v from 0 to 1): it would paint nothing (say, a
    centre given in pixels)."""
    (u0, v0), (u1, v1) = box
    if u1 < 0 or v1 < 0 or u0 > 1 or v0 > 1:
        raise InputError("lies wholly outside the texture, so it would paint nothing: u and v "
                         "are fractions of the texture, from 0 to 1", path, key=where)


def _known(table, keys, path, where):
    for k in table:
        if k not in keys:
            near = difflib.get_close_matches(k, sorted(keys), n=1, cutoff=0.5)
            hint = (f"; did you mean '{near[0]}'?" if near else
                    f"; expected {', '.join(sorted(keys))}")
            raise InputError(f"unknown key{hint}", path, key=f"{where}.{k}")


def _tables(value, path, where):
    if not isinstance(value, list) or not all(isinstance(t, dict) for t in value):
        raise InputError(f"expected [[{where.split('.', 2)[-1]}]] tables", path, key=where)
    return value
