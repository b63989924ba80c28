"""Scene files (TOML): what a render needs, validated, split into static config and params.

```toml
name = "hand"                      # default: the file's stem
[mesh]
file = "hand"                      # a built-in mesh name, or a path relative to this file
projection = "planar"              # planar | cylindrical | uv
[texture]
size = 512                         # texels across
[wrinkles]
enabled = true
k_scale = 1.1                      # 0.5–2 (lengths, in texels; static)
k_noise = 0.0                      # 0–1
k_bump = 0.5                       # 0–1
seed = 0
[material]
model = "blinn"                    # blinn | lafortune
melanin = 0.2                      # Blinn (eq. 5.7): melanin, blood 0–1; specular 0–1;
blood = 0.5                        #   shininess 0–10000
specular = 0.2
shininess = 100.0
brdf = "skin"                      # Lafortune: the preset, or a JSON from jaxskin fit-brdf
[light]
direction = [0.0, 0.0, 1.0]        # toward the light, camera space (parallel light)
ambient = 0.3                      # I_ambient
intensity = 0.7                    # I_light
[camera]
projection = "orthographic"        # orthographic | perspective
size = 512                         # image pixels across
supersample = 1                    # 1–4 samples per pixel per axis
fov = 30.0                         # perspective only, degrees
rotate = [0.0, 0.0, 0.0]           # degrees about x, y, z: turns the mesh
[view]
mode = "wrinkles"                  # wrinkles | overview (no wrinkles) | height
[[fields.edit]]                    # any number; none: the initial fields
at = [0.0, 0.4, 0.1]               # the vertex nearest to this point (or: vertex = 123)
d1 = [0.6, 1.0, 0.0]               # direction and magnitude (|d| <= 2)
d2 = [-0.8, 0.5, 0.0]
weight = 1.0                       # λ, 0–10
```

Every key has a type and a range; an unknown key is an error that suggests the nearest
valid one, an out-of-range value one that gives the range. `-D key=value` (like Mitsuba's)
overrides any value with the same checks. `Scene.config` (hashable: the jit cache key,
everything that changes which stages run or their shapes) and `Scene.params` (a dict of
arrays: everything differentiable) are the split the renderer uses.
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import tomllib
from pathlib import Path
from typing import Any

import jax.numpy as jnp

from .io import InputError, data_dir
from .mesh import BUILTIN as BUILTIN_MESHES
from .projection import KINDS

__all__ = ["BUILTIN_SCENES", "Scene", "SceneConfig", "TextureConfig", "builtin_scenes",
           "load_scene"]


@dataclasses.dataclass(frozen=True)
class _Key:
    kind: type
    default: Any
    lo: float | None = None
    hi: float | None = None
    choices: tuple | None = None
    param: bool = False  # differentiable (in Scene.params) rather than static


SCHEMA: dict[str, _Key] = {
    "name": _Key(str, None),
    "mesh.file": _Key(str, "hand"),
    "mesh.projection": _Key(str, "planar", choices=KINDS),
    "texture.size": _Key(int, 512, 16, 8192),
    "wrinkles.enabled": _Key(bool, True),
    "wrinkles.k_scale": _Key(float, 1.0, 0.5, 2.0),
    "wrinkles.k_noise": _Key(float, 0.0, 0.0, 1.0, param=True),
    "wrinkles.k_bump": _Key(float, 0.5, 0.0, 1.0, param=True),
    "wrinkles.seed": _Key(int, 0, 0, 2**31 - 1),
    "material.model": _Key(str, "blinn", choices=("blinn", "lafortune")),
    "material.melanin": _Key(float, 0.2, 0.0, 1.0, param=True),
    "material.blood": _Key(float, 0.5, 0.0, 1.0, param=True),
    "material.specular": _Key(float, 0.2, 0.0, 1.0, param=True),
    "material.shininess": _Key(float, 100.0, 0.0, 10000.0, param=True),
    "material.brdf": _Key(str, "skin"),
    "light.direction": _Key("vec3", (0.0, 0.0, 1.0), param=True),
    "light.ambient": _Key(float, 0.3, 0.0, 1.0, param=True),
    "light.intensity": _Key(float, 0.7, 0.0, 10.0, param=True),
    "camera.projection": _Key(str, "orthographic", choices=("orthographic", "perspective")),
    "camera.size": _Key(int, 512, 16, 8192),
    "camera.supersample": _Key(int, 1, 1, 4),
    "camera.fov": _Key(float, 30.0, 1.0, 120.0),
    "camera.rotate": _Key("vec3", (0.0, 0.0, 0.0)),
    "view.mode": _Key(str, "wrinkles", choices=("wrinkles", "overview", "height")),
}
# Parameters that only one material model uses: the other model's are left out.
_MODEL_PARAMS = {"blinn": {"material.melanin", "material.blood", "material.specular",
                           "material.shininess"}, "lafortune": set()}
EDIT_KEYS = {"at", "vertex", "d1", "d2", "weight"}


@dataclasses.dataclass(frozen=True)
class EditSpec:
    """A field edit as written: at a point (nearest vertex) or a vertex index."""

    at: tuple[float, float, float] | None
    vertex: int | None
    d1: tuple[float, float, float]
    d2: tuple[float, float, float]
    weight: float


@dataclasses.dataclass(frozen=True)
class TextureConfig:
    """What the texture-space maps depend on (the furrows are cached per one of these)."""

    mesh: str
    projection: str
    size: int
    wrinkles: bool
    k_scale: float
    seed: int
    edits: tuple[EditSpec, ...]


@dataclasses.dataclass(frozen=True)
class SceneConfig:
    """The static part of a scene (hashable; the jit cache key)."""

    texture: TextureConfig
    material: str  # blinn | lafortune
    brdf: str  # the Lafortune preset or file
    camera: str  # orthographic | perspective
    image: int
    supersample: int
    fov: float
    rotate: tuple[float, float, float]
    mode: str  # wrinkles | overview | height

    @property
    def needs_furrows(self) -> bool:
        return self.texture.wrinkles and self.mode in ("wrinkles", "height")


@dataclasses.dataclass(frozen=True)
class Scene:
    name: str
    source: str
    values: dict
    edits: tuple[EditSpec, ...]

    @functools.cached_property
    def config(self) -> SceneConfig:
        v = self.values
        tex = TextureConfig(v["mesh.file"], v["mesh.projection"], v["texture.size"],
                            v["wrinkles.enabled"], v["wrinkles.k_scale"], v["wrinkles.seed"],
                            self.edits)
        return SceneConfig(tex, v["material.model"], v["material.brdf"], v["camera.projection"],
                           v["camera.size"], v["camera.supersample"], v["camera.fov"],
                           tuple(v["camera.rotate"]), v["view.mode"])

    @functools.cached_property
    def params(self) -> dict:
        """Differentiable values as float32 arrays, keyed by their dotted names; only those
        the scene uses (no Blinn parameters in a Lafortune scene, no lobes in a Blinn one)."""
        model = self.values["material.model"]
        unused = set().union(*(p for m, p in _MODEL_PARAMS.items() if m != model))
        out = {k: jnp.asarray(self.values[k], jnp.float32) for k, spec in SCHEMA.items()
               if spec.param and k not in unused}
        if model == "lafortune":
            from .shading import lafortune

            brdf = self.values["material.brdf"]
            out["material.lafortune"] = (lafortune.skin() if brdf == "skin" else
                                         lafortune.load(brdf))
        return out


BUILTIN_SCENES = ("hand", "foot", "arm")


def builtin_scenes() -> dict[str, Path]:
    return {name: data_dir() / "scenes" / f"{name}.toml" for name in BUILTIN_SCENES}


def load_scene(name_or_path, overrides=()) -> Scene:
    """A built-in scene by name or a TOML scene file, with `-D key=value` `overrides`."""
    key = str(name_or_path)
    path = builtin_scenes().get(key, Path(key))
    if not path.is_file():
        raise InputError(f"no such scene file; built-in scenes: {', '.join(BUILTIN_SCENES)}",
                         path)
    try:
        doc = tomllib.loads(path.read_text(encoding="utf-8"))
    except (UnicodeDecodeError, OSError) as e:
        raise InputError(f"cannot read ({e.__class__.__name__})", path) from None
    except tomllib.TOMLDecodeError as e:
        raise InputError(f"not valid TOML: {e}", path) from None
    edits_raw = doc.get("fields", {}).pop("edit", []) if isinstance(doc.get("fields"), dict) \
        else []
    flat = _flatten(doc, path)
    values = {k: spec.default for k, spec in SCHEMA.items()}
    for k, v in flat.items():
        values[k] = _check(k, v, path)
    from_command_line = set()
    for item in overrides:
        k, v = _parse_override(item)
        values[k] = _check(k, v, f"-D {item}")
        from_command_line.add(k)

    def base(key):  # a path in the file is relative to it; one given with -D, to the cwd
        return Path.cwd() if key in from_command_line else path.parent

    if values["name"] is None:
        values["name"] = path.stem
    mesh = values["mesh.file"]
    if mesh not in BUILTIN_MESHES and not Path(mesh).is_absolute():
        values["mesh.file"] = str((base("mesh.file") / mesh).resolve())
    brdf = values["material.brdf"]
    if brdf != "skin":
        brdf_path = Path(brdf) if Path(brdf).is_absolute() else (
            base("material.brdf") / brdf).resolve()
        if not brdf_path.is_file():
            raise InputError("expected 'skin' (the preset) or a Lafortune JSON file (as "
                             f"written by jaxskin fit-brdf); no file {brdf_path}", path,
                             key="material.brdf")
        values["material.brdf"] = str(brdf_path)
    edits = tuple(_edit(i, e, path) for i, e in enumerate(edits_raw))
    return Scene(values["name"], str(path), values, edits)


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


def _check(key: str, value, where):
    spec = SCHEMA.get(key)
    if spec is None:
        near = difflib.get_close_matches(key, [*SCHEMA, "fields.edit"], n=1, cutoff=0.5)
        hint = f"; did you mean '{near[0]}'?" if near else f"; valid keys: {', '.join(SCHEMA)}"
        raise InputError(f"unknown key{hint}", where, key=key)
    kind = spec.kind
    if kind == "vec3":
        value = _vector(value, key, where)
        if spec.param and key == "light.direction" and not any(value):
            raise InputError("the light direction must not be zero", where, key=key)
        return value
    ok = isinstance(value, kind) and not (kind is not bool and isinstance(value, bool))
    if kind is float and isinstance(value, int) and not isinstance(value, bool):
        value, ok = float(value), True
    if not ok or (kind is float and not math.isfinite(value)):
        raise InputError(f"expected {'a finite number' if kind is float else kind.__name__}, "
                         f"got {value!r}", where, key=key)
    if spec.choices is not None and value not in spec.choices:
        raise InputError(f"must be one of {', '.join(spec.choices)}; got {value!r}", where,
                         key=key)
    if spec.lo is not None and not (spec.lo <= value <= spec.hi):
        raise InputError(f"must be in [{spec.lo:g}, {spec.hi:g}], got {value!r}", where, key=key)
    return value


def _parse_override(item: str):
    if "=" not in item:
        raise InputError(f"expected -D key=value, got {item!r}")
    key, text = (s.strip() for s in item.split("=", 1))
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text  # a bare word: a string
    return key, value


def _vector(value, key, path, limit=None):
    ok = isinstance(value, list) and len(value) == 3 and all(
        isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
        for c in value)
    if not ok:
        raise InputError(f"expected three finite numbers, got {value!r}", path, key=key)
    if limit is not None and math.hypot(*value) > limit + 1e-9:
        raise InputError(f"magnitude must be in [0, {limit:g}] (the paper's range), got "
                         f"{math.hypot(*value):.3g}", path, key=key)
    return tuple(float(c) for c in value)


def _edit(i, e, path) -> EditSpec:
    where = f"fields.edit[{i}]"
    if not isinstance(e, dict):
        raise InputError("expected a table with at (or vertex), d1, d2, weight", path, key=where)
    for k in e:
        if k not in EDIT_KEYS:
            near = difflib.get_close_matches(k, sorted(EDIT_KEYS), n=1, cutoff=0.5)
            hint = f"; did you mean '{near[0]}'?" if near else ""
            raise InputError(f"unknown key{hint}", path, key=f"{where}.{k}")
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
    at = _vector(e["at"], f"{where}.at", path) if "at" in e else None
    return EditSpec(at, vertex, _vector(e["d1"], f"{where}.d1", path, 2.0),
                    _vector(e["d2"], f"{where}.d2", path, 2.0), float(weight))
