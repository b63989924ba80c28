"""Scene files (TOML): what a render needs, validated, split into static config and params.

```toml
name = "hand"                      # default: the file's stem
[mesh]
file = "hand"                      # a built-in mesh name, or a path relative to this file
projection = "planar"              # planar | cylindrical | uv (unset: uv if the mesh has UVs)
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
brightness = 1.0                   # biophysical: a factor 0–2 on the skin's reflectance (a
                                   #   photo texture's shading and exposure: skin-maps)
brightness_image = "b.png"         # biophysical, optional: brightness × this greyscale map
colour_image = "c.png"             # biophysical, optional, with mask_image: an RGB image whose
                                   #   colour (a smooth spectrum of it) replaces the skin
                                   #   where mask_image is below 1
mask_image = "s.png"               # biophysical, optional, with colour_image: a greyscale
                                   #   mask, 1 on skin; below 1 colour_image shows there,
                                   #   under no cosmetic layer (skin-maps writes both)
# texture = "scan.png"             # biophysical, optional: a colour texture inverted into
                                   #   all of the above (jaxskin skin-maps' maps, at the
                                   #   scalars' defaults; they scale them), kept by jaxskin
                                   #   render in OUT/skin_maps_<hash>/ for the next run
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
                                   #   (letters, digits and _, at most 64 characters)
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

The package's private files:

- `_schema.py`: the keys (`SCHEMA`, `LAYER_SCHEMA`), their types, ranges and defaults.
- `_config.py`: `Scene` and its split: `SceneConfig` (static) and `Scene.params`.
- `_load.py`: `load_scene` and `parse_scene`: a file or a document read and checked.
- `_overrides.py`: `-D key=value` items and the type and range check of every value.
- `_tables.py`: the arrays of tables, `[[fields.edit]]` and `[[layer]]` with its regions.
- `_write.py`: TOML written: a scene (`scene_toml`) or a scene document (`dumps`).
"""

from __future__ import annotations

from ..texture import EditSpec as EditSpec
from ..texture import TextureConfig as TextureConfig
from ._config import PARALLEL_FROM_SIZE_ON_CPU as PARALLEL_FROM_SIZE_ON_CPU
from ._config import LayerSpec as LayerSpec
from ._config import Scene as Scene
from ._config import SceneConfig as SceneConfig
from ._config import SpectralConfig as SpectralConfig
from ._config import furrow_method as furrow_method
from ._config import param_keys as param_keys
from ._config import planar_side as planar_side
from ._load import BUILTIN_SCENES as BUILTIN_SCENES
from ._load import builtin_scenes as builtin_scenes
from ._load import kept_aspect as kept_aspect
from ._load import load_scene as load_scene
from ._load import parse_scene as parse_scene
from ._load import scene_at_width as scene_at_width
from ._load import toml_error as toml_error
from ._load import toml_text as toml_text
from ._overrides import check_value as check_value
from ._overrides import parse_override as parse_override
from ._schema import BIOPHYSICAL_KEYS as BIOPHYSICAL_KEYS
from ._schema import EDIT_KEYS as EDIT_KEYS
from ._schema import ELLIPSE_KEYS as ELLIPSE_KEYS
from ._schema import LAYER_KEYS as LAYER_KEYS
from ._schema import LAYER_SCHEMA as LAYER_SCHEMA
from ._schema import MODEL_PARAMS as MODEL_PARAMS
from ._schema import POLYGON_KEYS as POLYGON_KEYS
from ._schema import SCHEMA as SCHEMA
from ._schema import SKIN_MAPS as SKIN_MAPS
from ._schema import SKIN_MAPS_READ as SKIN_MAPS_READ
from ._schema import SPECTRAL_MODELS as SPECTRAL_MODELS
from ._schema import Key as Key
from ._write import dumps as dumps
from ._write import scene_toml as scene_toml
from ._write import value_text as value_text

__all__ = [
    "BIOPHYSICAL_KEYS", "BUILTIN_SCENES", "EDIT_KEYS", "ELLIPSE_KEYS", "LAYER_KEYS",
    "LAYER_SCHEMA", "MODEL_PARAMS", "PARALLEL_FROM_SIZE_ON_CPU", "POLYGON_KEYS", "SCHEMA",
    "SKIN_MAPS", "SKIN_MAPS_READ", "SPECTRAL_MODELS", "EditSpec", "Key", "LayerSpec", "Scene",
    "SceneConfig", "SpectralConfig", "TextureConfig", "builtin_scenes", "check_value", "dumps",
    "furrow_method", "kept_aspect", "load_scene", "param_keys", "parse_override", "parse_scene",
    "planar_side", "scene_at_width", "scene_toml", "toml_error", "toml_text", "value_text",
]
