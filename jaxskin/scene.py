"""Scene files (TOML): what a render needs, validated, split into static config and params.

```toml
name = "hand"                      # default: the file's stem
[mesh]
file = "hand"                      # a built-in mesh name, or a path relative to this file
projection = "planar"              # planar | cylindrical | uv
[texture]
size = 512                         # texels across
[wrinkles]
enabled = true                     # false: no furrow program at all (a smooth surface)
k_scale = 1.0                      # 0.5–2 (lengths, in texels; static)
k_noise = 0.0                      # 0–1: noise added to the height field
k_bump = 0.5                       # 0–1: depth of the bump mapping
seed = 0                           # the furrows' random numbers
method = "auto"                    # auto | parallel | sequential: the furrow program (static;
                                   #   auto: parallel on a GPU/TPU, and on a CPU from 2048²)
[material]
model = "blinn"                    # blinn | lafortune | spectral (the cosmetics model) |
                                   #   biophysical (the cosmetics model over a biophysical skin)
melanin = 0.2                      # Blinn's skin colour: melanin 0–1 (shading.blinn)
blood = 0.5                        # Blinn's skin colour: blood 0–1
specular = 0.2                     # Blinn's specular reflectance 0–1
shininess = 100.0                  # Blinn's exponent 0–10000
brdf = "skin"                      # Lafortune: the preset, or a JSON from jaxskin fit-brdf
[light]
direction = [0.0, 0.0, 1.0]        # toward the light, camera space (parallel light)
ambient = 0.3                      # I_ambient: irradiance reaching every point
intensity = 0.7                    # I_light: the light's irradiance at normal incidence
                                   #   (units: a white matte surface facing the light shows
                                   #   ambient + intensity, linear, before the exposure)
shadows = false                    # a shadow map from the light (static: the direction above)
[camera]
projection = "orthographic"        # orthographic | perspective
exposure = 0.0                     # stops: the linear image × 2^exposure, then sRGB
size = 512                         # image pixels across
height = 0                         # image pixels high; 0: square. A -D camera.size alone
                                   #   scales a height set here with it (same aspect)
supersample = 2                    # 1–4 samples per pixel per axis (2: antialiased)
fov = 30.0                         # perspective only, degrees
rotate = [0.0, 0.0, 0.0]           # degrees: turns the mesh about x, then y, then z (fixed axes)
zoom = 1.0                         # 1–64: magnifies the frame about `center` (a close-up;
                                   #   raise texture.size with it to keep texels small)
center = [0.0, 0.0]                # the point zoomed into, in fractions of the whole
                                   #   frame from its middle, x right and y up (-0.5–0.5)
[view]
mode = "wrinkles"                  # wrinkles | overview (no wrinkles) | height
[[fields.edit]]                    # any number; none: the initial fields
at = [0.0, 0.4, 0.1]               # the vertex nearest to this point ...
# vertex = 123                     # ... or a vertex index instead (give one of the two)
d1 = [0.6, 1.0, 0.0]               # direction and magnitude (|d| <= 2) of the first field
d2 = [-0.8, 0.5, 0.0]              # ... and of the second
weight = 1.0                       # λ, 0–10
```

The cosmetics model (Huang et al. 2013, `material.model = "spectral"`) adds:

```toml
[mesh]
unit_mm = 10.0                     # millimetres per mesh unit (the face is in cm)
[skin]
model = "nist"                     # nist (a measured subject) | biophysical
subject = 1                        # NIST skin spectrum, subjects 1–100
melanin = 0.0                      # added melanin, optical depth at 500 nm (0–3)
melanin_fraction = 0.06            # biophysical skin (jaxskin.biophysical): melanosome
                                   #   volume fraction 0.005–0.5
eumelanin = 0.1                    # biophysical: the eumelanin share 0–1 (the rest pheomelanin)
haemoglobin = 0.02                 # biophysical: dermal blood volume fraction 0.001–0.1
oxygenation = 0.6                  # biophysical: the blood's oxygen saturation 0–1
epidermis_mm = 0.035               # biophysical: epidermis thickness 0.01–0.15 mm
scattering = 2.5                   # biophysical: scattering factor 0.5–6
melanin_image = "melanin.png"      # optional: a greyscale map, melanin × its value (0–1)
melanin_fraction_image = "m.png"   # biophysical, optional: melanin_fraction × this greyscale
                                   #   map (0–1) per texel (as fit-image writes one)
haemoglobin_image = "h.png"        # biophysical, optional: haemoglobin × this greyscale map
roughness = 0.3                    # Kelemen m of the skin's own highlight
specular = 0.18                    # Kelemen rho_s of the skin's own highlight
[spectral]
step = 10                          # nm: 1 | 5 | 10 | 20
illuminant = "D65"                 # D65 | D55 | D50 | A, adapted to D65 white (CAT02):
                                   #   white stays white; colours shift only a little
[sss]
enabled = true                     # false: no subsurface scattering blur at all
method = "fft"                     # fft (exact) | separable (3-sigma passes)
texel_mm = 0.0                     # 0: from the mesh's scale and UV area
[[layer]]                          # any number, bottom (applied first) to top
name = "blush"                     # names the layer's keys: -D layer.blush.thickness_mm=0.02
material = "blush_rose"            # a shipped material, or a jaxskin calibrate JSON
thickness_mm = 0.01                # thickness where the map is 1
roughness = 0.3                    # its highlight: Kelemen m
specular = 0.1                     # its highlight: Kelemen rho_s
s_scale = 1.0                      # multiplies the material's S(λ)
k_scale = 1.0                      # multiplies the material's K(λ)
# image = "blush.png"              # a greyscale map (0–1 × thickness_mm), or the regions
                                   #   below, not both; none of image, ellipse, polygon:
                                   #   everywhere
[[layer.ellipse]]                  # ellipses on the mesh's UVs (u right, v up), feathered;
                                   #   the map is the union of the regions
center = [0.28, 0.47]              # uv
radii = [0.08, 0.05]               # uv units
angle = 0.0                        # degrees
feather = 0.03                     # soft edge width, uv units
[[layer.polygon]]                  # polygons on the mesh's UVs, feathered
vertices = [61, 146, 91]           # mesh vertices (their UVs) ...
# points = [[0.4, 0.2], [0.6, 0.2], [0.5, 0.3]]  # ... or uv points (give one of the two)
feather = 0.01                     # soft edge width, uv units
```

Every key has a type and a range; an unknown key is an error that suggests the nearest
valid one, an out-of-range value one that gives the range. `-D key=value` (like Mitsuba's)
overrides any value with the same checks. `Scene.config` (hashable: the jit cache key,
everything that changes which stages run or their shapes) and `Scene.params` (a dict of
arrays: everything differentiable) are the split the renderer uses.
"""

from __future__ import annotations

import copy
import dataclasses
import difflib
import functools
import math
import re
import tomllib
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp

from . import biophysical, cosmetics
from .io import InputError, data_dir
from .mesh import BUILTIN as BUILTIN_MESHES
from .projection import KINDS
from .spectral import ILLUMINANTS, STEPS, Grid

__all__ = ["BUILTIN_SCENES", "Scene", "SceneConfig", "TextureConfig", "builtin_scenes",
           "load_scene", "param_keys", "parse_scene", "scene_at_width"]


@dataclasses.dataclass(frozen=True)
class _Key:
    kind: type
    default: Any
    lo: float | None = None
    hi: float | None = None
    choices: tuple | None = None
    param: bool = False  # differentiable (in Scene.params) rather than static


# The skin's per-texel maps: the map key (a fit's `(H, W)` param) → the scalar it
# multiplies and the scene key of the greyscale image that loads one.
SKIN_MAPS = {"skin.melanin_map": ("skin.melanin", "skin.melanin_image"),
             "skin.melanin_fraction_map": ("skin.melanin_fraction",
                                           "skin.melanin_fraction_image"),
             "skin.haemoglobin_map": ("skin.haemoglobin", "skin.haemoglobin_image")}
# The skin maps each skin model reads (`SceneConfig.skin_model`): a map another model's
# scene sets is left out of its config and warned about (`checks.idle_maps`).
SKIN_MAPS_READ = {"nist": ("skin.melanin_map",),
                  "biophysical": ("skin.melanin_fraction_map", "skin.haemoglobin_map")}
# The biophysical skin's parameters (`biophysical.Skin` fields) as scene keys.
BIOPHYSICAL_KEYS = {"melanin": "skin.melanin_fraction", "eumelanin": "skin.eumelanin",
                    "haemoglobin": "skin.haemoglobin", "oxygenation": "skin.oxygenation",
                    "epidermis_mm": "skin.epidermis_mm", "scattering": "skin.scattering"}

SCHEMA: dict[str, _Key] = {
    "name": _Key(str, None),
    "mesh.file": _Key(str, "hand"),
    "mesh.projection": _Key(str, "planar", choices=KINDS),
    "mesh.unit_mm": _Key(float, 1.0, 1e-6, 1e6),
    "texture.size": _Key(int, 512, 16, 8192),
    "wrinkles.enabled": _Key(bool, True),
    "wrinkles.k_scale": _Key(float, 1.0, 0.5, 2.0),
    "wrinkles.k_noise": _Key(float, 0.0, 0.0, 1.0, param=True),
    "wrinkles.k_bump": _Key(float, 0.5, 0.0, 1.0, param=True),
    "wrinkles.seed": _Key(int, 0, 0, 2**31 - 1),
    "wrinkles.method": _Key(str, "auto", choices=("auto", "parallel", "sequential")),
    "material.model": _Key(str, "blinn", choices=("blinn", "lafortune", "spectral",
                                                  "biophysical")),
    "material.melanin": _Key(float, 0.2, 0.0, 1.0, param=True),
    "material.blood": _Key(float, 0.5, 0.0, 1.0, param=True),
    "material.specular": _Key(float, 0.2, 0.0, 1.0, param=True),
    "material.shininess": _Key(float, 100.0, 0.0, 10000.0, param=True),
    "material.brdf": _Key(str, "skin"),
    "light.direction": _Key("vec3", (0.0, 0.0, 1.0), param=True),
    "light.ambient": _Key(float, 0.3, 0.0, 1.0, param=True),
    "light.intensity": _Key(float, 0.7, 0.0, 10.0, param=True),
    "light.shadows": _Key(bool, False),
    "camera.projection": _Key(str, "orthographic", choices=("orthographic", "perspective")),
    "camera.size": _Key(int, 512, 16, 8192),
    "camera.height": _Key(int, 0, 0, 8192),
    "camera.supersample": _Key(int, 2, 1, 4),
    "camera.fov": _Key(float, 30.0, 1.0, 120.0),
    "camera.exposure": _Key(float, 0.0, -20.0, 20.0, param=True),
    "camera.rotate": _Key("vec3", (0.0, 0.0, 0.0)),
    "camera.zoom": _Key(float, 1.0, 1.0, 64.0),
    "camera.center": _Key("vec2", (0.0, 0.0), -0.5, 0.5),
    "view.mode": _Key(str, "wrinkles", choices=("wrinkles", "overview", "height")),
    "skin.model": _Key(str, "nist", choices=("nist", "biophysical")),
    "skin.subject": _Key(int, 1, 1, 100),
    "skin.melanin": _Key(float, 0.0, 0.0, 3.0, param=True),
    "skin.roughness": _Key(float, 0.3, 0.01, 1.0, param=True),
    "skin.specular": _Key(float, 0.18, 0.0, 1.0, param=True),
    "skin.melanin_image": _Key(str, None),  # a greyscale map (0–1 × skin.melanin) per texel
    "skin.melanin_fraction_image": _Key(str, None),  # biophysical: × skin.melanin_fraction
    "skin.haemoglobin_image": _Key(str, None),  # biophysical: × skin.haemoglobin
    # The biophysical skin (`jaxskin.biophysical`): its parameters, ranges and defaults.
    **{key: _Key(float, float(getattr(biophysical.DEFAULT, name)),
                 *biophysical.RANGES[name], param=True)
       for name, key in BIOPHYSICAL_KEYS.items()},
    "spectral.step": _Key(int, 10, choices=STEPS),
    "spectral.illuminant": _Key(str, "D65", choices=ILLUMINANTS),
    "sss.enabled": _Key(bool, True),
    "sss.method": _Key(str, "fft", choices=("fft", "separable")),
    "sss.texel_mm": _Key(float, 0.0, 0.0, 100.0),
}
# Per cosmetic layer, as `layer.<name>.<key>` (in the file: inside its [[layer]] table).
LAYER_SCHEMA: dict[str, _Key] = {
    "thickness_mm": _Key(float, 0.01, 0.0, 10.0, param=True),
    "roughness": _Key(float, 0.3, 0.01, 1.0, param=True),
    "specular": _Key(float, 0.1, 0.0, 1.0, param=True),
    "s_scale": _Key(float, 1.0, 0.0, 100.0, param=True),
    "k_scale": _Key(float, 1.0, 0.0, 100.0, param=True),
}
LAYER_KEYS = {"name", "material", "image", "ellipse", "polygon", *LAYER_SCHEMA}
ELLIPSE_KEYS = {"center", "radii", "angle", "feather"}
POLYGON_KEYS = {"points", "vertices", "feather"}
# Parameters that only one material model uses: the other model's are left out.
_SPECTRAL_PARAMS = {"skin.melanin", "skin.roughness", "skin.specular",
                    *BIOPHYSICAL_KEYS.values()}
_MODEL_PARAMS = {"blinn": {"material.melanin", "material.blood", "material.specular",
                           "material.shininess"}, "lafortune": set(),
                 "spectral": _SPECTRAL_PARAMS, "biophysical": _SPECTRAL_PARAMS}
SPECTRAL_MODELS = ("spectral", "biophysical")  # the models that shade through the spectra
EDIT_KEYS = {"at", "vertex", "d1", "d2", "weight"}


@dataclasses.dataclass(frozen=True)
class EditSpec:
    """A field edit as written: at a point (nearest vertex) or a vertex index."""

    at: tuple[float, float, float] | None
    vertex: int | None
    d1: tuple[float, float, float]
    d2: tuple[float, float, float]
    weight: float


def planar_side(projection: str, rotate) -> str:
    """The texture's projection for a scene's `mesh.projection` and `camera.rotate`: a
    planar map whose camera sees the side facing −z (the hand turned round) gives that
    side the texels the two sides share ("planar-back"), so that the side in view is
    shaded with its own normals (it was the +z side's: a flat, unlit silhouette; a trial).
    The camera looks down −z at the mesh turned by `view.rotation(rotate)` (x, then y, then
    z): the mesh's direction toward it has z = cos(x) cos(y)."""
    if projection != "planar":
        return projection
    ax, ay = (math.radians(float(a)) for a in tuple(rotate)[:2])
    return "planar-back" if math.cos(ax) * math.cos(ay) < 0 else "planar"


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
    # The furrow program: "sequential" (wrinkles.height_field) or "parallel"
    # (lockstep.height_field); the scene's "auto" is resolved by `furrow_method`.
    method: str = "sequential"


@dataclasses.dataclass(frozen=True)
class LayerSpec:
    """A cosmetic layer's static part: its material and where it lies. `ellipses`:
    `(center, radii, angle, feather)`; `polygons`: `(points, vertices, feather)` with one of
    points (uv) or vertices (mesh indices) set."""

    name: str
    material: str  # the material file's absolute path
    image: str | None
    ellipses: tuple = ()
    polygons: tuple = ()


@dataclasses.dataclass(frozen=True)
class SpectralConfig:
    """The static part of the cosmetics model (`material.model = "spectral"`)."""

    subject: int
    step: int
    illuminant: str
    unit_mm: float
    sss: str | None  # the blur method, or None: no subsurface scattering
    texel_mm: float  # 0: from the mesh
    layers: tuple[LayerSpec, ...]
    skin: str = "nist"  # the skin under the layers: a NIST subject, or "biophysical"
    melanin_image: str | None = None  # skin.melanin × this greyscale map, per texel
    melanin_fraction_image: str | None = None  # biophysical: the melanin fraction's map
    haemoglobin_image: str | None = None  # biophysical: the haemoglobin fraction's map

    def image_of(self, map_key: str) -> str | None:
        """The greyscale image file of a skin map key (`SKIN_MAPS`), or None."""
        return getattr(self, SKIN_MAPS[map_key][1].split(".")[1])

    @property
    def grid(self) -> Grid:
        """The spectral `Grid` of `step` and `illuminant`."""
        return Grid(self.step, illuminant=self.illuminant)


@dataclasses.dataclass(frozen=True)
class SceneConfig:
    """The static part of a scene (hashable; the jit cache key)."""

    texture: TextureConfig
    material: str  # blinn | lafortune | spectral | biophysical
    brdf: str  # the Lafortune preset or file
    camera: str  # orthographic | perspective
    image: int
    supersample: int
    fov: float
    rotate: tuple[float, float, float]
    mode: str  # wrinkles | overview | height
    spectral: SpectralConfig | None = None  # the cosmetics model's, when it is the material
    image_height: int = 0  # 0: square
    # The light direction (camera space) the shadow map is made for; None: no shadows.
    shadow: tuple[float, float, float] | None = None
    zoom: float = 1.0  # camera.zoom: the frame magnified about `center`
    center: tuple[float, float] = (0.0, 0.0)  # camera.center, fractions of the frame, y up

    @property
    def needs_furrows(self) -> bool:
        """Whether the render runs the furrow program (wrinkles on and a mode that shows
        them)."""
        return self.texture.wrinkles and self.mode in ("wrinkles", "height")


# The texture size from which "auto" picks the parallel furrow program on a CPU: where it
# is as quick from a cold start (trace, compile, first run: what a one-off render pays) as
# the sequential one. Measured on the hand, 2 cores (benchmarks/RESULTS.md, "Parallel furrow
# program"), the furrow program alone, cold, sequential / parallel: 2.4 / 3.3–3.4 s at
# 512², 2.6–3.0 / 3.6–3.9 s at 1024², 4.0–4.3 / 3.4–4.6 s at 2048², 10.4 / 8.1 s at 4096²;
# warm the parallel one is 1.9–4.5x quicker (512² to 2048², three runs; on 2026-12-04, an
# Intel VM, cold 1.5 / 2.2 s at 512², 2.4 / 2.3 s at 1536², 3.2 / 2.5 s at 2048²).
PARALLEL_FROM_SIZE_ON_CPU = 2048


def furrow_method(method: str, size: int = 512) -> str:
    """`wrinkles.method` resolved for a `size`² texture: "auto" is the parallel program on
    a GPU or TPU (on an H200 8.4 ms at 512² and 12.2 ms at 2048², where the sequential one
    took 0.72 s and 8.9 s, slower than on a CPU),
    and on a CPU the one that is quicker there from a cold start: the sequential one below
    `PARALLEL_FROM_SIZE_ON_CPU` (so the built-in scenes, all 512², keep the look their golden
    images pin), the parallel one from it."""
    if method != "auto":
        return method
    import jax

    if jax.default_backend() != "cpu":
        return "parallel"
    return "parallel" if size >= PARALLEL_FROM_SIZE_ON_CPU else "sequential"


@dataclasses.dataclass(frozen=True)
class Scene:
    """A loaded, checked scene: `values` (every key's value), the field `edits` and
    cosmetic `layers`; `config` and `params` split it for the renderer."""

    name: str
    source: str
    values: dict
    edits: tuple[EditSpec, ...]
    layers: tuple[LayerSpec, ...] = ()

    @functools.cached_property
    def config(self) -> SceneConfig:
        """The static part of the scene, hashable: the jit cache key."""
        v = self.values
        tex = TextureConfig(v["mesh.file"], planar_side(v["mesh.projection"],
                                                        v["camera.rotate"]), v["texture.size"],
                            v["wrinkles.enabled"], v["wrinkles.k_scale"], v["wrinkles.seed"],
                            self.edits,
                            furrow_method(v["wrinkles.method"], v["texture.size"]))
        spectral = None
        if v["material.model"] in SPECTRAL_MODELS:
            spectral = SpectralConfig(v["skin.subject"], v["spectral.step"],
                                      v["spectral.illuminant"], v["mesh.unit_mm"],
                                      v["sss.method"] if v["sss.enabled"] else None,
                                      v["sss.texel_mm"], self.layers, self.skin_model,
                                      *(v[image] if key in SKIN_MAPS_READ[self.skin_model]
                                        else None for key, (_, image) in SKIN_MAPS.items()))
        # The BRDF file only where the Lafortune model reads it: another model's config
        # (its jit key) does not change with it, and `-D material.brdf=...` on a Blinn
        # scene is reported as changing nothing (`checks.unused_overrides`).
        brdf = v["material.brdf"] if v["material.model"] == "lafortune" else "skin"
        # Likewise the field of view only where a perspective camera has one (-D camera.fov
        # on an orthographic scene was the same image without a word, a trial).
        fov = (v["camera.fov"] if v["camera.projection"] == "perspective"
               else SCHEMA["camera.fov"].default)
        return SceneConfig(tex, v["material.model"], brdf, v["camera.projection"],
                           v["camera.size"], v["camera.supersample"], fov,
                           tuple(v["camera.rotate"]), v["view.mode"], spectral,
                           v["camera.height"],
                           tuple(v["light.direction"]) if v["light.shadows"] else None,
                           v["camera.zoom"], tuple(v["camera.center"]))

    @property
    def skin_model(self) -> str:
        """The skin of a spectral scene: "biophysical" (`material.model = "biophysical"`,
        or `skin.model = "biophysical"`) or "nist" (a measured subject)."""
        v = self.values
        return "biophysical" if v["material.model"] == "biophysical" else v["skin.model"]

    @functools.cached_property
    def params(self) -> dict:
        """Differentiable values as float32 arrays, keyed by their dotted names; only those
        the scene uses (no Blinn parameters in a Lafortune scene, no lobes in a Blinn one)."""
        model = self.values["material.model"]
        keys = param_keys(model, self.skin_model, [layer.name for layer in self.layers])
        # Concrete arrays even when first read inside a jit: there jnp.asarray of a list is
        # a tracer, which this cache kept, and the next call failed (UnexpectedTracerError)
        with jax.ensure_compile_time_eval():
            out = {k: jnp.asarray(self.values[k], jnp.float32) for k in keys
                   if k != "material.lafortune"}
            if model == "lafortune":
                from .formats import read_lafortune
                from .shading import lafortune

                brdf = self.values["material.brdf"]
                out["material.lafortune"] = (lafortune.skin() if brdf == "skin" else
                                             read_lafortune(brdf))
        return out


def param_keys(model: str, skin: str, layers) -> list[str]:
    """The keys of `Scene.params` for material `model`, skin model `skin` ("nist" or
    "biophysical"; read by the spectral models only) and cosmetic layers named `layers`:
    every differentiable scene key the model uses (no Blinn parameters in a Lafortune
    scene, no lobes in a Blinn one, one skin's keys), the layers' keys, and
    `material.lafortune` for the Lafortune model; not the optional per-texel maps."""
    unused = set().union(*(p for m, p in _MODEL_PARAMS.items() if m != model))
    unused -= _MODEL_PARAMS[model]
    if model in SPECTRAL_MODELS:  # one skin: the measured one's or the biophysical's
        unused |= ({"skin.melanin"} if skin == "biophysical" else
                   set(BIOPHYSICAL_KEYS.values()))
    keys = [k for k, spec in SCHEMA.items() if spec.param and k not in unused]
    keys += [f"layer.{name}.{k}" for name in layers for k in LAYER_SCHEMA]
    return keys + (["material.lafortune"] if model == "lafortune" else [])


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
    if not path.is_file():  # named as given: `./hand` was shown as `hand` (a trial)
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
        raise (InputError(other, path) if other else _toml_error(e, path)) from None
    return parse_scene(doc, path, overrides, flag=flag)


def _other_file(raw: bytes, path) -> str | None:
    """What a file given as a scene that is not TOML is, when it is one of the project's
    other files (a material JSON, a measurement CSV): render once said only "not valid
    TOML" of a material that calibrate wrote (a trial)."""
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


def _toml_error(e, path) -> InputError:
    """tomllib's error as `file:line: not valid TOML: what (column C)`: the line in the
    place every other error puts it (it said "… (at line 2, column 6)" at the end)."""
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
    given = overrides
    text = isinstance(given, (str, bytes, dict))
    overrides = [] if text else list(given)
    if (text and given) or not all(isinstance(item, str) for item in overrides):
        # a string was read character by character ("expected key=value, got 't'")
        raise TypeError(f"overrides: expected a list of 'key=value' strings, got "
                        f"{type(given).__name__} {given!r:.60}")
    allow = allow or (lambda key, file: None)
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
    values = {k: spec.default for k, spec in SCHEMA.items()}
    materials = _material_overrides(overrides, flag)
    layers = tuple(_layer(i, e, path, values, materials, allow)
                   for i, e in enumerate(layers_raw))
    names = [layer.name for layer in layers]
    for name in names:
        if names.count(name) > 1:
            raise InputError(f"two layers are named {name!r}; names must differ", path,
                             key="layer.name")
    flat = _flatten(doc, path)
    for k, v in flat.items():
        values[k] = _check(k, v, path)
    from_command_line = {}  # key → the override that set it last, as errors name it
    for item in overrides:
        k, v = _parse_override(item, flag)
        parts = k.split(".")
        if len(parts) == 3 and parts[0] == "layer":
            if parts[1] not in names:
                near = difflib.get_close_matches(parts[1], names, n=1, cutoff=0.5)
                hint = f"did you mean '{near[0]}'? " if near else ""
                raise InputError(f"scene {path.name} has no layer named {parts[1]!r} ({hint}its "
                                 f"layers: {', '.join(names) or 'none'}; -D applies to every "
                                 "scene a command renders)", f"{flag} {item}", key=k)
            if parts[2] == "material":
                continue  # a layer's material: taken by _layer
        values[k] = _check(k, v, f"{flag} {item}", names)
        from_command_line[k] = f"{flag} {item}"
    if "camera.size" in from_command_line and "camera.height" not in from_command_line:
        values["camera.height"] = _kept_aspect(values, flat.get("camera.size",
                                                                SCHEMA["camera.size"].default),
                                               from_command_line["camera.size"])
    if layers and values["material.model"] not in SPECTRAL_MODELS:
        raise InputError("cosmetic layers need material.model = \"spectral\" or "
                         "\"biophysical\" (the Huang et al. model); this scene's is "
                         f"{values['material.model']!r}", path, key="layer")
    given_skin = from_command_line.get("skin.model", path if "skin.model" in flat else None)
    if (values["material.model"] == "biophysical" and values["skin.model"] == "nist"
            and given_skin is not None):
        # material.model = "biophysical" means a biophysical skin: an explicit nist skin
        # beside it was silently ignored (a newcomer's trial)
        raise InputError("material.model = \"biophysical\" renders the biophysical skin, so "
                         "skin.model = \"nist\" cannot hold; for the measured skin use "
                         "material.model = \"spectral\"", given_skin, key="skin.model")

    def base(key):  # a path in the file is relative to it; one given with -D, to the cwd
        return Path.cwd() if key in from_command_line else path.parent

    def source(key):  # where a value came from, for its error: the file or the -D item
        return from_command_line.get(key, path)

    if values["name"] is None:
        values["name"] = path.stem
    mesh = values["mesh.file"]
    if mesh not in BUILTIN_MESHES:
        if not Path(mesh).is_absolute():
            values["mesh.file"] = str((base("mesh.file") / mesh).resolve())
        allow("mesh.file", Path(values["mesh.file"]).resolve())
        if not Path(values["mesh.file"]).is_file():  # named with the file and key (a trial)
            raise InputError(f"expected a built-in mesh ({', '.join(BUILTIN_MESHES)}) or a mesh "
                             f"file; no file {values['mesh.file']}", source("mesh.file"),
                             key="mesh.file")
    brdf = values["material.brdf"]
    if brdf != "skin":
        brdf_path = Path(brdf) if Path(brdf).is_absolute() else (
            base("material.brdf") / brdf).resolve()
        allow("material.brdf", brdf_path.resolve())
        if not brdf_path.is_file():
            raise InputError("expected 'skin' (the preset) or a Lafortune JSON file (as "
                             f"written by jaxskin fit-brdf); no file {brdf_path}",
                             source("material.brdf"), key="material.brdf")
        values["material.brdf"] = str(brdf_path)
    for _, image_key in SKIN_MAPS.values():
        image = values[image_key]
        if image is None:
            continue
        image_path = Path(image) if Path(image).is_absolute() else (
            base(image_key) / image).resolve()
        allow(image_key, image_path.resolve())
        if not image_path.is_file():
            what = ("is a folder" if image_path.is_dir() else "not a regular file"
                    if image_path.exists() else "no such file")
            raise InputError(f"{what}: {image_path} (expected a greyscale image file)",
                             source(image_key), key=image_key)
        values[image_key] = str(image_path)
    edits = tuple(_edit(i, e, path) for i, e in enumerate(edits_raw))
    return Scene(values["name"], str(path), values, edits, layers)


def _kept_aspect(values: dict, file_size: int, origin: str) -> int:
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


def _check(key: str, value, where, layers=()):
    spec = SCHEMA.get(key)
    parts = key.split(".")
    if spec is None and len(parts) == 3 and parts[0] == "layer":
        if parts[1] not in layers:
            raise InputError(f"no layer named {parts[1]!r} (this scene's layers: "
                             f"{', '.join(layers) or 'none'})", where, key=key)
        spec = LAYER_SCHEMA.get(parts[2])
        if spec is None:
            raise InputError("a layer's value to set must be one of "
                             f"{', '.join([*LAYER_SCHEMA, 'material'])}", where, key=key)
    if key in ("fields.edit", "layer"):  # "unknown key; did you mean 'fields.edit'?" before
        table = "[[fields.edit]]" if key == "fields.edit" else "[[layer]]"
        raise InputError(f"{table} tables are written in a scene file; they cannot be set as "
                         "one value", where, key=key)
    sections = {k.split(".")[0] for k in SCHEMA if "." in k} | {"fields", "layer"}
    if spec is None and len(parts) > 1 and parts[0] not in sections:
        near = difflib.get_close_matches(parts[0], sorted(sections), n=1, cutoff=0.5)
        fixed = ".".join([*near[:1], *parts[1:]])
        hint = (f"did you mean '{fixed}'?" if fixed in SCHEMA else f"did you mean [{near[0]}]?"
                if near else f"the tables are {', '.join(f'[{t}]' for t in sorted(sections))}")
        raise InputError(f"unknown table [{parts[0]}]; {hint}", where, key=key)
    if spec is None:
        near = difflib.get_close_matches(key, [*SCHEMA, "fields.edit", "layer"], n=1,
                                         cutoff=0.5)
        hint = f"; did you mean '{near[0]}'?" if near else f"; valid keys: {', '.join(SCHEMA)}"
        raise InputError(f"unknown key{hint}", where, key=key)
    kind = spec.kind
    if kind == "vec2":
        value = _vector(value, key, where, n=2)
        if not all(spec.lo <= c <= spec.hi for c in value):
            raise InputError(f"each number must be in [{spec.lo:g}, {spec.hi:g}], got "
                             f"{list(value)!r}", where, key=key)
        return value
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
                         f"got {value!r}{_comma_hint(value) if kind is float else ''}", where,
                         key=key)
    if spec.choices is not None and value not in spec.choices:
        raise InputError(f"must be one of {', '.join(map(str, spec.choices))}; got {value!r}",
                         where,
                         key=key)
    if spec.lo is not None and not (spec.lo <= value <= spec.hi):
        raise InputError(f"must be in [{spec.lo:g}, {spec.hi:g}], got {value!r}", where, key=key)
    return value


# A number's point with no digit before it (.5) or after it (5.), where a number may stand:
# a 0 is put there (0.5, 5.0) before TOML reads it.
_POINT_ALONE = re.compile(r"(?:(?<=^)|(?<=[\s,\[+-]))(\.)(?=\d)|(?<=\d)(\.)(?![\d\w])")


def _parse_override(item: str, flag: str = "-D"):
    if "=" not in item:
        raise InputError(f"expected {flag} key=value, got {item!r}")
    key, text = (s.strip() for s in item.split("=", 1))
    spec = SCHEMA.get(key)
    numeric = (spec.kind in (float, int, "vec2", "vec3") if spec is not None else
               key.startswith("layer.") and key.rsplit(".", 1)[-1] in LAYER_SCHEMA)
    if numeric:  # .5 and 5. as 0.5 and 5.0 (TOML wants digits on both sides of the point:
        text = _POINT_ALONE.sub(lambda m: "0." if m[1] else ".0", text)  # a trial's .5)
    try:
        value = tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        value = text  # a bare word: a string
        if spec is not None and spec.kind in ("vec2", "vec3"):  # numbers with commas, as
            try:  # typed without brackets (camera.rotate=0,60,0 was a string; a trial); a
                items = tomllib.loads(f"v = [{text}]")["v"]  # scalar's 0,5 stays '0,5'
            except tomllib.TOMLDecodeError:
                items = []
            if len(items) > 1 and all(isinstance(c, (int, float)) and not isinstance(c, bool)
                                      for c in items):
                value = items
    return key, value


def _finite_list(value, n: int, positive: bool = False) -> bool:
    """Whether `value` is a list of `n` finite numbers (all > 0 if `positive`)."""
    return isinstance(value, list) and len(value) == n and all(
        isinstance(c, (int, float)) and not isinstance(c, bool) and math.isfinite(c)
        and (c > 0 or not positive) for c in value)


def _vector(value, key, path, limit=None, n=3):
    if not _finite_list(value, n):
        raise InputError(f"expected {('two', 'three')[n - 2]} finite numbers "
                         f"({('[x, y]', '[x, y, z]')[n - 2]}), got {value!r}", path, key=key)
    if limit is not None and math.hypot(*value) > limit + 1e-9:
        raise InputError(f"magnitude must be in [0, {limit:g}] (the paper's range), got "
                         f"{math.hypot(*value):.3g}", path, key=key)
    return tuple(float(c) for c in value)


def _edit(i, e, path) -> EditSpec:
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
    at = _vector(e["at"], f"{where}.at", path) if "at" in e else None
    return EditSpec(at, vertex, _vector(e["d1"], f"{where}.d1", path, 2.0),
                    _vector(e["d2"], f"{where}.d2", path, 2.0), float(weight))


def _material_overrides(overrides, flag: str) -> dict:
    """`-D layer.NAME.material=...` items: `{NAME: (value, item)}`, the last one given
    winning (a name that is no layer's is left for `_check` to report)."""
    out = {}
    for item in overrides:
        k, v = _parse_override(item, flag)
        parts = k.split(".")
        if len(parts) == 3 and parts[0] == "layer" and parts[2] == "material":
            out[parts[1]] = (v, f"{flag} {item}")
    return out


def _layer(i, e, path, values, materials=None, allow=lambda key, file: None) -> LayerSpec:
    """One [[layer]] table: its static spec; its parameters go into `values`. `materials`:
    `_material_overrides`, which replace the table's material (a path taken from the
    working directory, as any path given with -D)."""
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
    where = f"layer.{name}"
    for k, spec in LAYER_SCHEMA.items():
        values[f"{where}.{k}"] = _check(f"{where}.{k}", e.get(k, spec.default), path, (name,))
    material, source, base = e.get("material"), path, path.parent
    if name in (materials or {}):
        (material, source), base = materials[name], Path.cwd()
    if not isinstance(material, str) or not material:
        raise InputError("expected a material: a shipped one's name or a JSON file written "
                         "by jaxskin calibrate", source, key=f"{where}.material")
    file = cosmetics.material_path(material, base)
    allow(f"{where}.material", file.resolve())
    if file.exists() and not file.is_file():  # /dev/zero said "no material file" (a trial)
        raise InputError(f"not a regular file: {file} (expected a material JSON written by "
                         "jaxskin calibrate)", source, key=f"{where}.material")
    if not file.is_file():
        shipped = cosmetics.shipped_materials()
        near = difflib.get_close_matches(material, shipped, n=1, cutoff=0.75)
        hint = f"did you mean '{near[0]}'? " if near else ""
        raise InputError(f"no material file {file} ({hint}shipped materials: "
                         f"{', '.join(shipped)})", source, key=f"{where}.material")
    cosmetics.check_material(file)  # readable and covering the render grid, before any work
    material = str(file)
    image = e.get("image")
    if image is not None:
        if not isinstance(image, str):
            raise InputError(f"expected a greyscale image file, got {image!r}", path,
                             key=f"{where}.image")
        allow(f"{where}.image", (path.parent / image).resolve())
        if not (path.parent / image).is_file():
            raise InputError(f"no such file {(path.parent / image).resolve()} (expected a "
                             "greyscale image file, taken from the scene file's folder)", path,
                             key=f"{where}.image")
        image = str((path.parent / image).resolve())
    ellipses, polygons = [], []
    for j, r in enumerate(_tables(e.get("ellipse", []), path, f"{where}.ellipse")):
        w = f"{where}.ellipse[{j}]"
        _known(r, ELLIPSE_KEYS, path, w)
        center = _numbers(r.get("center"), 2, path, f"{w}.center")
        radii = _numbers(r.get("radii"), 2, path, f"{w}.radii", positive=True)
        feather = _number(r.get("feather", 0.0), path, f"{w}.feather", lo=0.0)
        reach = max(radii) + feather
        _on_texture([(center[0] - reach, center[1] - reach),
                     (center[0] + reach, center[1] + reach)], path, w)
        ellipses.append((center, radii, _number(r.get("angle", 0.0), path, f"{w}.angle"),
                         feather))
    for j, r in enumerate(_tables(e.get("polygon", []), path, f"{where}.polygon")):
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
            points = tuple(_numbers(q, 2, path, f"{w}.points") for q in pts)
            reach = _number(r.get("feather", 0.0), path, f"{w}.feather", lo=0.0)
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
                         _number(r.get("feather", 0.0), path, f"{w}.feather", lo=0.0)))
    if image is not None and (ellipses or polygons):
        raise InputError("give an image or regions (ellipse, polygon), not both", path,
                         key=where)
    return LayerSpec(name, material, image, tuple(ellipses), tuple(polygons))


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


def _comma_hint(value) -> str:
    """A hint for a number written with a decimal comma (`-D skin.melanin=0,5`)."""
    if isinstance(value, str) and re.fullmatch(r"[+-]?\d*,\d+", value.strip()):
        return f" (a decimal comma? write {value.strip().replace(',', '.')})"
    return ""


def _number(value, path, where, lo=None):
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(
            value) or (lo is not None and value < lo):
        bound = f" >= {lo:g}" if lo is not None else ""
        raise InputError(f"expected a finite number{bound}, got {value!r}{_comma_hint(value)}",
                         path, key=where)
    return float(value)


def _numbers(value, n, path, where, positive=False):
    if not _finite_list(value, n, positive):
        raise InputError(f"expected {n} finite{' positive' if positive else ''} numbers, got "
                         f"{value!r}", path, key=where)
    return tuple(float(c) for c in value)


def check_value(key: str, value, where, layers=()):
    """`value` for `key`, checked as a scene file's or `-D`'s value is (type, range); an
    `InputError` naming `where` and the key otherwise. `layers`: the scene's layer names."""
    return _check(key, value, where, tuple(layers))
parse_override = _parse_override  # TEMP
