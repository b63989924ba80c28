"""The loaded scene (`Scene`) and its split for the renderer: the static, hashable
`SceneConfig` (the jit cache key) and the differentiable `Scene.params`."""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp

from ..spectral import Grid
from ..texture import EditSpec, TextureConfig
from ._schema import (
    BIOPHYSICAL_KEYS,
    LAYER_SCHEMA,
    MODEL_PARAMS,
    OWN_COLOUR_KEYS,
    SCHEMA,
    SKIN_MAPS,
    SKIN_MAPS_READ,
    SPECTRAL_MODELS,
)


def planar_side(projection: str, rotate) -> str:
    """The texture's projection for a scene's `mesh.projection` and `camera.rotate`: a
    planar map whose camera sees the side facing −z (the hand turned round) gives that
    side the texels the two sides share ("planar-back"), so that the side in view is
    shaded with its own normals (with the +z side's it would be a flat, unlit silhouette).
    The camera looks down −z at the mesh turned by `view.rotation(rotate)` (x, then y, then
    z): the mesh's direction toward it has z = cos(x) cos(y)."""
    if projection != "planar":
        return projection
    ax, ay = (math.radians(float(a)) for a in tuple(rotate)[:2])
    return "planar-back" if math.cos(ax) * math.cos(ay) < 0 else "planar"


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
    brightness_image: str | None = None  # biophysical: the brightness's map
    colour_image: str | None = None  # biophysical: the colour where the mask is below 1
    mask_image: str | None = None  # biophysical: 1 where the skin is (skin.mask_image)
    texture: str | None = None  # biophysical: skin.texture, inverted into the maps above
    texture_fixed: tuple = ()  # its inversion's held values (`skin_maps.Fixed`)

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
# the sequential one; below it the sequential one is quicker cold, while warm the parallel
# one is quicker at every size (the measurements: benchmarks/RESULTS.md, "Parallel furrow
# program").
PARALLEL_FROM_SIZE_ON_CPU = 2048


def furrow_method(method: str, size: int = 512) -> str:
    """`wrinkles.method` resolved for a `size`² texture: "auto" is the parallel program on
    a GPU or TPU (there it is milliseconds where the sequential one takes about a second or
    more, slower than on a CPU: benchmarks/RESULTS.md),
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
                                        else None for key, (_, image) in SKIN_MAPS.items()),
                                      *(v[key] if self.skin_model == "biophysical" else None
                                        for key in OWN_COLOUR_KEYS),
                                      *self._texture())
        # The BRDF file only where the Lafortune model reads it: another model's config
        # (its jit key) does not change with it, and `-D material.brdf=...` on a Blinn
        # scene is reported as changing nothing (`checks.unused_overrides`).
        brdf = v["material.brdf"] if v["material.model"] == "lafortune" else "skin"
        # Likewise the field of view only where a perspective camera has one, so that
        # -D camera.fov on an orthographic scene is reported as changing nothing.
        fov = (v["camera.fov"] if v["camera.projection"] == "perspective"
               else SCHEMA["camera.fov"].default)
        return SceneConfig(tex, v["material.model"], brdf, v["camera.projection"],
                           v["camera.size"], v["camera.supersample"], fov,
                           tuple(v["camera.rotate"]), v["view.mode"], spectral,
                           v["camera.height"],
                           tuple(v["light.direction"]) if v["light.shadows"] else None,
                           v["camera.zoom"], tuple(v["camera.center"]))

    def _texture(self) -> tuple:
        """`(skin.texture, the values its inversion holds)` for `SpectralConfig`: its
        eumelanin, oxygenation, epidermis and scattering are the scene's."""
        v = self.values
        if self.skin_model != "biophysical" or v["skin.texture"] is None:
            return None, ()
        return v["skin.texture"], tuple(float(v[BIOPHYSICAL_KEYS[name]]) for name in (
            "eumelanin", "oxygenation", "epidermis_mm", "scattering"))

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
        # a tracer, which this cache would keep for the next call (UnexpectedTracerError)
        with jax.ensure_compile_time_eval():
            out = {k: jnp.asarray(self.values[k], jnp.float32) for k in keys
                   if k != "material.lafortune"}
            if model == "lafortune":
                from ..formats import read_lafortune
                from ..shading import lafortune

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
    unused = set().union(*(p for m, p in MODEL_PARAMS.items() if m != model))
    unused -= MODEL_PARAMS[model]
    if model in SPECTRAL_MODELS:  # one skin: the measured one's or the biophysical's
        unused |= ({"skin.melanin"} if skin == "biophysical" else
                   {*BIOPHYSICAL_KEYS.values(), "skin.brightness"})
    keys = [k for k, spec in SCHEMA.items() if spec.param and k not in unused]
    keys += [f"layer.{name}.{k}" for name in layers for k in LAYER_SCHEMA]
    return keys + (["material.lafortune"] if model == "lafortune" else [])
