"""Loading a scene: a built-in name or a TOML file, read, checked and split (`parse_scene`)."""

from __future__ import annotations

import copy
import difflib
import re
import tomllib
from pathlib import Path

from ..io import InputError, data_dir, real_path
from ..mesh import BUILTIN as BUILTIN_MESHES
from ..mesh import default_projection
from ._config import Scene
from ._overrides import check_value, material_overrides, parse_override
from ._schema import OWN_COLOUR_KEYS, SCHEMA, SKIN_MAPS, SPECTRAL_MODELS
from ._tables import parse_edit, parse_layer

BUILTIN_SCENES = ("hand", "foot", "arm", "face", "makeup")


def builtin_scenes() -> dict[str, Path]:
    """`{name: path}` of the built-in scene files in `data/scenes/`."""
    return {name: data_dir() / "scenes" / f"{name}.toml" for name in BUILTIN_SCENES}


def scene_at_width(name_or_path, width: int, overrides=(), *, flag: str = "override") -> Scene:
    """The scene with its image `width` pixels wide; a scene that sets `camera.height` (a
    wide or tall frame) keeps its aspect, so small renders (tests, the gallery) frame it
    as its default view does."""
    scene = load_scene(name_or_path, overrides, flag=flag)
    size, height = scene.values["camera.size"], scene.values["camera.height"]
    extra = [f"camera.size={width}"]
    if height:
        extra.append(f"camera.height={max(16, round(height * width / size))}")
    return load_scene(name_or_path, [*overrides, *extra], flag=flag)


def load_scene(name_or_path, overrides=(), *, flag: str = "override") -> Scene:
    """A built-in scene by name or a TOML scene file, with `"key=value"` `overrides` (the
    command line's `-D`). An error caused by an override names it as `flag` and the item
    (`override texture.size=abc: key 'texture.size': ...`; the command line passes
    `flag="-D"`)."""
    key = str(name_or_path)
    path = builtin_scenes().get(key, Path(key))
    if path.is_dir():
        raise InputError("is a folder; expected a TOML scene file or a built-in scene "
                         f"({', '.join(BUILTIN_SCENES)})", path)
    if path.exists() and not path.is_file():  # a FIFO would block the read below
        raise InputError("not a regular file (a FIFO or a device); expected a TOML scene "
                         "file", path)
    if not path.is_file():  # named as given (`./hand`, not `hand`: the file looked for)
        hint = f"built-in scenes: {', '.join(BUILTIN_SCENES)}"
        if Path(key).name in BUILTIN_SCENES and key not in BUILTIN_SCENES:
            hint = f"the built-in scene is '{Path(key).name}', without the folder"
        raise InputError(f"no such scene file; {hint}", key)
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read ({e.strerror or e.__class__.__name__})", path) from None
    if raw.startswith((b"\x89PNG", b"\xff\xd8\xff", b"\x76\x2f\x31\x01", b"II*\x00",
                       b"MM\x00*")):  # PNG, JPEG, OpenEXR, TIFF
        raise InputError("an image, not a TOML scene file: an image is named in a scene "
                         "(a [[layer]]'s image, skin.melanin_image, ...); render takes "
                         "scenes", path)
    try:
        doc = tomllib.loads(toml_text(raw, path))
    except tomllib.TOMLDecodeError as e:
        other = _other_file(raw, path)
        raise (InputError(other, path) if other else toml_error(e, path)) from None
    return parse_scene(doc, path, overrides, flag=flag)


def _other_file(raw: bytes, path) -> str | None:
    """What a file given as a scene that is not TOML is, when it is one of the project's
    other files (a material JSON, a measurement CSV), so that the error says what the
    file is and where it belongs rather than only "not valid TOML"."""
    head = raw[:4096].decode("utf-8-sig", "replace").lstrip()
    if path.suffix.lower() == ".json" or head.startswith("{"):
        return ("a JSON file, not a TOML scene file: a calibrated material (what calibrate "
                "writes) is named by a scene's [[layer]] material = \"FILE.json\", a "
                "Lafortune fit (fit-brdf) by material.brdf")
    first = next((line for line in head.splitlines()
                  if line.strip() and not line.lstrip().startswith("#")), "")
    if (path.suffix.lower() in (".csv", ".tsv", ".txt") and "=" not in first
            and re.search(r"[,;\t]", first)):  # a row of cells, not a TOML line
        return ("a table, not a TOML scene file: measurements are calibrated with 'jaxskin "
                "calibrate', BRDF samples fitted with 'jaxskin fit-brdf', skin spectra with "
                "'jaxskin fit-skin'; render takes TOML scenes (docs/reference/scene.md)")
    return None


def toml_error(e, path) -> InputError:
    """tomllib's error as `file:line: not valid TOML: what (column C)`: the line in the
    place every other error puts it (tomllib puts "… (at line 2, column 6)" at the end)."""
    message = str(e.args[0]) if e.args else str(e)
    m = re.search(r"\s*\(at line (\d+), column (\d+)\)$", message)
    if m is None:
        return InputError(f"not valid TOML: {message}", path)
    return InputError(f"not valid TOML: {message[:m.start()]} (column {m[2]})", path,
                      int(m[1]))


def toml_text(raw: bytes, path) -> str:
    """A TOML scene file's bytes as text: UTF-8, with or without the byte-order mark that
    Windows editors write; `InputError` naming `path` for anything else."""
    if raw.startswith((b"\xff\xfe", b"\xfe\xff")):
        raise InputError("is UTF-16 text; a TOML file is UTF-8: save it as UTF-8", path)
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise InputError(f"is not UTF-8 text (byte {e.start}); expected a TOML scene file, "
                         "saved as UTF-8", path) from None


def parse_scene(doc: dict, path, overrides=(), allow=None, *, flag: str = "override") -> Scene:
    """A scene from its parsed TOML document `doc` (as `tomllib` gives it; not changed), read
    as if from the file `path` (relative paths are taken from its folder), with `-D`
    `overrides`: what `load_scene` does after reading the file (the editor builds scenes
    from documents it holds). `allow(key, path)`, if given, is called with every file the
    scene names (resolved) before that file is looked at or read, and raises to refuse it:
    the editor confines a scene from the page to its folders so, and no error then tells
    whether a file outside them exists. `flag`: as in `load_scene`."""
    path = Path(path)
    overrides = _override_items(overrides)
    allow = allow or (lambda key, file: None)
    doc, edits_raw, layers_raw = _split_tables(doc, path)
    values = {k: spec.default for k, spec in SCHEMA.items()}
    layers = _layers(layers_raw, path, values, material_overrides(overrides, flag), allow)
    names = [layer.name for layer in layers]
    flat = _flatten(doc, path)
    for k, v in flat.items():
        values[k] = check_value(k, v, path)
    from_command_line = _apply_overrides(values, overrides, flag, path, names)
    if "camera.size" in from_command_line and "camera.height" not in from_command_line:
        values["camera.height"] = kept_aspect(values, flat.get("camera.size",
                                                               SCHEMA["camera.size"].default),
                                              from_command_line["camera.size"])
    _check_models(values, layers, path, "skin.model" in flat, from_command_line)
    if values["name"] is None:
        values["name"] = path.stem
    _resolve_files(values, path, from_command_line, allow)
    if "mesh.projection" not in flat and "mesh.projection" not in from_command_line:
        values["mesh.projection"] = default_projection(values["mesh.file"])
    edits = tuple(parse_edit(i, e, path) for i, e in enumerate(edits_raw))
    return Scene(values["name"], str(path), values, edits, layers)


def _override_items(given) -> list[str]:
    """The `-D` overrides as a list of `"key=value"` strings (any iterable of them);
    `TypeError` for anything else."""
    text = isinstance(given, (str, bytes, dict))
    overrides = [] if text else list(given)
    if (text and given) or not all(isinstance(item, str) for item in overrides):
        # a string was read character by character ("expected key=value, got 't'")
        raise TypeError(f"overrides: expected a list of 'key=value' strings, got "
                        f"{type(given).__name__} {given!r:.60}")
    return overrides


def _split_tables(doc: dict, path: Path) -> tuple[dict, list, list]:
    """`(a copy of doc without them, the [[fields.edit]] tables, the [[layer]] tables)`;
    `InputError` when either is not an array of tables."""
    doc = copy.deepcopy(doc)
    edits_raw = doc.get("fields", {}).pop("edit", []) if isinstance(doc.get("fields"), dict) \
        else []
    if not isinstance(edits_raw, list):  # [fields.edit] written for [[fields.edit]]
        raise InputError("expected [[fields.edit]] tables, one per edit (an array of "
                         "tables: two brackets), got one [fields.edit] table", path,
                         key="fields.edit")
    layers_raw = doc.pop("layer", [])
    if not isinstance(layers_raw, list):
        raise InputError("expected [[layer]] tables (an array of tables)", path, key="layer")
    return doc, edits_raw, layers_raw


def _layers(layers_raw: list, path: Path, values: dict, materials: dict, allow) -> tuple:
    """The `LayerSpec`s of the [[layer]] tables (`parse_layer`; their values go into
    `values`); `InputError` when two share a name."""
    layers = tuple(parse_layer(i, e, path, values, materials, allow)
                   for i, e in enumerate(layers_raw))
    names = [layer.name for layer in layers]
    for name in names:
        if names.count(name) > 1:
            raise InputError(f"two layers are named {name!r}; names must differ", path,
                             key="layer.name")
    return layers


def _apply_overrides(values: dict, overrides: list, flag: str, path: Path, names) -> dict:
    """The `-D` `overrides` checked and set in `values` (a layer's material aside: that is
    `parse_layer`'s); `names`: the scene's layers. Returns `{key: the item that set it
    last}`, as errors name it."""
    from_command_line = {}
    for item in overrides:
        k, v = parse_override(item, flag)
        parts = k.split(".")
        if len(parts) == 3 and parts[0] == "layer":
            if parts[1] not in names:
                near = difflib.get_close_matches(parts[1], names, n=1, cutoff=0.5)
                hint = f"did you mean '{near[0]}'? " if near else ""
                raise InputError(f"scene {path.name} has no layer named {parts[1]!r} ({hint}its "
                                 f"layers: {', '.join(names) or 'none'}; -D applies to every "
                                 "scene a command renders)", f"{flag} {item}", key=k)
            if parts[2] == "material":
                continue  # a layer's material: taken by parse_layer
        values[k] = check_value(k, v, f"{flag} {item}", names)
        from_command_line[k] = f"{flag} {item}"
    return from_command_line


def _check_models(values: dict, layers: tuple, path: Path, skin_in_file: bool,
                  from_command_line: dict) -> None:
    """`InputError` for a material model that cannot hold with the rest: cosmetic layers
    without a spectral model, or a biophysical material with `skin.model = "nist"` given
    (in the file, `skin_in_file`, or with -D)."""
    if layers and values["material.model"] not in SPECTRAL_MODELS:
        raise InputError("cosmetic layers need material.model = \"spectral\" or "
                         "\"biophysical\" (the Huang et al. model); this scene's is "
                         f"{values['material.model']!r}", path, key="layer")
    given_skin = from_command_line.get("skin.model", path if skin_in_file else None)
    if (values["material.model"] == "biophysical" and values["skin.model"] == "nist"
            and given_skin is not None):
        # material.model = "biophysical" means a biophysical skin: an explicit nist skin
        # beside it would be ignored in silence
        raise InputError("material.model = \"biophysical\" renders the biophysical skin, so "
                         "skin.model = \"nist\" cannot hold; for the measured skin use "
                         "material.model = \"spectral\"", given_skin, key="skin.model")


def _resolve_files(values: dict, path: Path, from_command_line: dict, allow) -> None:
    """The files `values` names (a mesh that is not a built-in one, a BRDF file, the skin
    maps' images) made absolute in place, each passed to `allow` and checked to exist."""

    def base(key):  # a path in the file is relative to it; one given with -D, to the cwd
        return Path.cwd() if key in from_command_line else path.parent

    def source(key):  # where a value came from, for its error: the file or the -D item
        return from_command_line.get(key, path)

    mesh = values["mesh.file"]
    if mesh not in BUILTIN_MESHES:
        if not Path(mesh).is_absolute():
            values["mesh.file"] = str(real_path(base("mesh.file") / mesh))
        allow("mesh.file", real_path(values["mesh.file"]))
        mesh_path = Path(values["mesh.file"])
        if not mesh_path.is_file():  # named with the file and key; a FIFO would hang trimesh
            what = ("is a folder" if mesh_path.is_dir() else "not a regular file"
                    if mesh_path.exists() else "no file")
            raise InputError(f"expected a built-in mesh ({', '.join(BUILTIN_MESHES)}) or a mesh "
                             f"file; {what} {mesh_path}" if what == "no file" else
                             f"{what}: {mesh_path} (expected a built-in mesh "
                             f"({', '.join(BUILTIN_MESHES)}) or a mesh file)",
                             source("mesh.file"), key="mesh.file")
    brdf = values["material.brdf"]
    if brdf != "skin":
        brdf_path = Path(brdf) if Path(brdf).is_absolute() else real_path(
            base("material.brdf") / brdf)
        allow("material.brdf", real_path(brdf_path))
        if not brdf_path.is_file():
            raise InputError("expected 'skin' (the preset) or a Lafortune JSON file (as "
                             "written by jaxskin fit-brdf); "
                             + ("not a regular file" if brdf_path.exists() else "no file")
                             + f" {brdf_path}",
                             source("material.brdf"), key="material.brdf")
        values["material.brdf"] = str(brdf_path)
    given = [key for key in OWN_COLOUR_KEYS if values[key] is not None]
    if len(given) == 1:  # a colour without its mask (or the reverse) says nothing
        other = [key for key in OWN_COLOUR_KEYS if key not in given][0]
        raise InputError(f"{given[0]} needs {other} too (both or neither; jaxskin skin-maps "
                         "writes the mask)", source(given[0]), key=given[0])
    if values["skin.texture"] is not None:  # its maps, or the images: not both
        for key in [image for _, image in SKIN_MAPS.values()] + list(OWN_COLOUR_KEYS):
            if values[key] is not None and key != "skin.melanin_image":
                raise InputError(f"skin.texture gives the skin's maps; {key} gives one too: "
                                 "give one of the two", source(key), key=key)
    for image_key in [image for _, image in SKIN_MAPS.values()] + [*OWN_COLOUR_KEYS,
                                                                    "skin.texture"]:
        image = values[image_key]
        if image is None:
            continue
        image_path = Path(image) if Path(image).is_absolute() else real_path(
            base(image_key) / image)
        allow(image_key, real_path(image_path))
        if not image_path.is_file():
            what = ("is a folder" if image_path.is_dir() else "not a regular file"
                    if image_path.exists() else "no such file")
            kind = "a greyscale" if image_key.endswith("_image") and image_key not in (
                OWN_COLOUR_KEYS[0],) else "a colour"
            raise InputError(f"{what}: {image_path} (expected {kind} image file)",
                             source(image_key), key=image_key)
        values[image_key] = str(image_path)


def kept_aspect(values: dict, file_size: int, origin: str) -> int:
    """`camera.height` for a `-D camera.size` given alone: a scene file that sets
    `camera.height` (a wide or tall frame) keeps its aspect, the height scaled with the
    width (rounded, at least 1 pixel); `InputError` when that height is over the key's
    maximum, naming `origin` (the override). A square scene (height 0) stays square."""
    height, size = values["camera.height"], values["camera.size"]
    if not height:
        return 0
    scaled = max(1, round(height * size / file_size))
    top = SCHEMA["camera.height"].hi
    if scaled > top:
        raise InputError(f"expected at most {top * file_size // height} for this scene's "
                         f"{file_size}x{height} frame (the height keeps its aspect: "
                         f"{size}x{scaled}, over {top}); give camera.height too (0: square)",
                         origin, key="camera.size")
    return scaled


def _flatten(doc, path, prefix="") -> dict:
    out = {}
    for k, v in doc.items():
        dotted = f"{prefix}{k}"
        if isinstance(v, dict):
            if not v and dotted == "fields":
                continue
            out.update(_flatten(v, path, dotted + "."))
        else:
            out[dotted] = v
    return out
