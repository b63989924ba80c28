"""The scene keys: each one's type, default, range and whether it is differentiable."""

from __future__ import annotations

import dataclasses
from typing import Any

from .. import biophysical
from ..projection import KINDS
from ..spectral import ILLUMINANTS, STEPS


@dataclasses.dataclass(frozen=True)
class Key:
    """A scene key: its type (`kind`: a Python type, or "vec2"/"vec3"), default, range
    (`lo`, `hi`) or `choices`, and whether it is differentiable."""

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
             "skin.haemoglobin_map": ("skin.haemoglobin", "skin.haemoglobin_image"),
             "skin.brightness_map": ("skin.brightness", "skin.brightness_image")}
# The skin maps each skin model reads (`SceneConfig.skin_model`): a map another model's
# scene sets is left out of its config and warned about (`checks.idle_maps`).
SKIN_MAPS_READ = {"nist": ("skin.melanin_map",),
                  "biophysical": ("skin.melanin_fraction_map", "skin.haemoglobin_map",
                                  "skin.brightness_map")}
# The biophysical skin's parameters (`biophysical.Skin` fields) as scene keys.
# Images a biophysical skin reads besides its maps: a colour and its mask (both or neither).
OWN_COLOUR_KEYS = ("skin.colour_image", "skin.mask_image")
BIOPHYSICAL_KEYS = {"melanin": "skin.melanin_fraction", "eumelanin": "skin.eumelanin",
                    "haemoglobin": "skin.haemoglobin", "oxygenation": "skin.oxygenation",
                    "epidermis_mm": "skin.epidermis_mm", "scattering": "skin.scattering"}

SCHEMA: dict[str, Key] = {
    "name": Key(str, None),
    "mesh.file": Key(str, "hand"),
    "mesh.projection": Key(str, "planar", choices=KINDS),
    "mesh.unit_mm": Key(float, 1.0, 1e-6, 1e6),
    "texture.size": Key(int, 512, 16, 8192),
    "wrinkles.enabled": Key(bool, True),
    "wrinkles.k_scale": Key(float, 1.0, 0.5, 2.0),
    "wrinkles.k_noise": Key(float, 0.0, 0.0, 1.0, param=True),
    "wrinkles.k_bump": Key(float, 0.5, 0.0, 1.0, param=True),
    "wrinkles.seed": Key(int, 0, 0, 2**31 - 1),
    "wrinkles.method": Key(str, "auto", choices=("auto", "parallel", "sequential")),
    "material.model": Key(str, "blinn", choices=("blinn", "lafortune", "spectral",
                                                  "biophysical")),
    "material.melanin": Key(float, 0.2, 0.0, 1.0, param=True),
    "material.blood": Key(float, 0.5, 0.0, 1.0, param=True),
    "material.specular": Key(float, 0.2, 0.0, 1.0, param=True),
    "material.shininess": Key(float, 100.0, 0.0, 10000.0, param=True),
    "material.brdf": Key(str, "skin"),
    "light.direction": Key("vec3", (0.0, 0.0, 1.0), param=True),
    "light.ambient": Key(float, 0.3, 0.0, 1.0, param=True),
    "light.intensity": Key(float, 0.7, 0.0, 10.0, param=True),
    "light.shadows": Key(bool, False),
    "camera.projection": Key(str, "orthographic", choices=("orthographic", "perspective")),
    "camera.size": Key(int, 512, 16, 8192),
    "camera.height": Key(int, 0, 0, 8192),
    "camera.supersample": Key(int, 2, 1, 4),
    "camera.fov": Key(float, 30.0, 1.0, 120.0),
    "camera.exposure": Key(float, 0.0, -20.0, 20.0, param=True),
    "camera.rotate": Key("vec3", (0.0, 0.0, 0.0)),
    "camera.zoom": Key(float, 1.0, 1.0, 64.0),
    "camera.center": Key("vec2", (0.0, 0.0), -0.5, 0.5),
    "view.mode": Key(str, "wrinkles", choices=("wrinkles", "overview", "height")),
    "skin.model": Key(str, "nist", choices=("nist", "biophysical")),
    "skin.subject": Key(int, 1, 1, 100),
    "skin.melanin": Key(float, 0.0, 0.0, 3.0, param=True),
    "skin.roughness": Key(float, 0.3, 0.01, 1.0, param=True),
    "skin.specular": Key(float, 0.18, 0.0, 1.0, param=True),
    "skin.melanin_image": Key(str, None),  # a greyscale map (0–1 × skin.melanin) per texel
    "skin.melanin_fraction_image": Key(str, None),  # biophysical: × skin.melanin_fraction
    "skin.haemoglobin_image": Key(str, None),  # biophysical: × skin.haemoglobin
    # biophysical: a factor on the skin's diffuse reflectance (a photo texture's shading and
    # exposure, `jaxskin.skin_maps`), and its map (× skin.brightness)
    "skin.brightness": Key(float, 1.0, 0.0, 2.0, param=True),
    "skin.brightness_image": Key(str, None),
    # biophysical: where skin.mask_image is below 1, the skin's reflectance gives way to a
    # smooth spectrum of skin.colour_image's colour (`skin_maps.upsample`): eyes, hair, lips
    "skin.colour_image": Key(str, None),
    "skin.mask_image": Key(str, None),
    # biophysical: a colour texture inverted into all of the above (`jaxskin.skin_maps`)
    "skin.texture": Key(str, None),
    # The biophysical skin (`jaxskin.biophysical`): its parameters, ranges and defaults.
    **{key: Key(float, float(getattr(biophysical.DEFAULT, name)),
                 *biophysical.RANGES[name], param=True)
       for name, key in BIOPHYSICAL_KEYS.items()},
    "spectral.step": Key(int, 10, choices=STEPS),
    "spectral.illuminant": Key(str, "D65", choices=ILLUMINANTS),
    "sss.enabled": Key(bool, True),
    "sss.method": Key(str, "fft", choices=("fft", "separable")),
    "sss.texel_mm": Key(float, 0.0, 0.0, 100.0),
}
# Per cosmetic layer, as `layer.<name>.<key>` (in the file: inside its [[layer]] table).
LAYER_SCHEMA: dict[str, Key] = {
    "thickness_mm": Key(float, 0.01, 0.0, 10.0, param=True),
    "roughness": Key(float, 0.3, 0.01, 1.0, param=True),
    "specular": Key(float, 0.1, 0.0, 1.0, param=True),
    "s_scale": Key(float, 1.0, 0.0, 100.0, param=True),
    "k_scale": Key(float, 1.0, 0.0, 100.0, param=True),
}
LAYER_KEYS = {"name", "material", "image", "ellipse", "polygon", *LAYER_SCHEMA}
ELLIPSE_KEYS = {"center", "radii", "angle", "feather"}
POLYGON_KEYS = {"points", "vertices", "feather"}
# Parameters that only one material model uses: the other model's are left out.
_SPECTRAL_PARAMS = {"skin.melanin", "skin.roughness", "skin.specular", "skin.brightness",
                    *BIOPHYSICAL_KEYS.values()}
MODEL_PARAMS = {"blinn": {"material.melanin", "material.blood", "material.specular",
                          "material.shininess"}, "lafortune": set(),
                "spectral": _SPECTRAL_PARAMS, "biophysical": _SPECTRAL_PARAMS}
SPECTRAL_MODELS = ("spectral", "biophysical")  # the models that shade through the spectra
EDIT_KEYS = {"at", "vertex", "d1", "d2", "weight"}
