"""The cosmetics model's skin, texel by texel: what `render.prepare` loads for it and the
reflectance the render computes from it.

- `skin_arrays`: the arrays a scene's skin needs, per texel on the mesh: the NIST subject's
  spectrum or the biophysical model's chromophores, each skin map read from its image (a
  factor on its scalar: `skin.melanin_image`, …), the texture's own colour where
  `skin.mask_image` says it is not skin (`own_colour`), and `skin.texture`'s inverted maps
  (`texture_arrays`).
- `skin_reflectance`: the skin's diffuse reflectance on the spectral grid, per texel where a
  map varies it: the NIST subject darkened by melanin (`jaxskin.skin`) or the biophysical
  model (`jaxskin.biophysical`).
- `texel_map`, `map_cover`: a per-texel map given as a parameter (a fit's) or loaded by
  the scene, and the name of the loaded one.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from . import biophysical, cosmetics, formats, maps, skin
from .scene import BIOPHYSICAL_KEYS, SKIN_MAPS

__all__ = ["map_cover", "own_colour", "skin_arrays", "skin_reflectance", "texel_map",
           "texture_arrays"]


def skin_arrays(sp, height: int, width: int, texels) -> dict:
    """What the skin of the cosmetics model `sp` (a `SpectralConfig`) reads, for a texture
    of `height × width` texels and its texels on the mesh `texels` (flat indices): `skin`
    `(n,)` (the NIST subject's spectrum on the grid) or `chromophores (6, n)` (μa, μs' of the
    biophysical model's absorbers), each map loaded from an image as `map_cover(key) (P,)`,
    and `own_colour`'s and `texture_arrays`' arrays where the scene has them."""
    grid = sp.grid
    if sp.skin == "biophysical":  # μa, μs' of the absorbers on the grid, (6, n)
        arrays = {"chromophores": jnp.asarray(np.stack(biophysical.chromophores(
            grid.wavelengths, formats.haemoglobin_table())), jnp.float32)}
    else:
        arrays = {"skin": jnp.asarray(formats.nist_reflectance(sp.subject, grid),
                                      jnp.float32)}
    for map_key in SKIN_MAPS:  # e.g. skin.melanin × skin.melanin_image, per texel
        if sp.image_of(map_key) is not None:
            factor = cosmetics.image_map(maps.read_grey(sp.image_of(map_key)), height, width,
                                         1.0)
            arrays[map_cover(map_key)] = jnp.asarray(factor.reshape(-1)[texels], jnp.float32)
    if sp.mask_image is not None:  # the texture's own colour where the skin is not
        arrays.update(own_colour(sp, height, width, texels))
    if sp.texture is not None:  # skin.texture: its maps, mask and colour
        arrays.update(texture_arrays(sp, height, width, texels))
    return arrays


def own_colour(sp, height: int, width: int, texels, rgb=None, mask=None) -> dict:
    """`skin.colour_image` and `skin.mask_image` (or the arrays `rgb (H', W', 3)`, `mask
    (H', W')`) per texel on the mesh: `own_weight (P,)` (1 − the mask: how much of the
    texel is the image's colour, not the skin) and `own_R (P, n)` (that colour's smooth
    spectrum on the grid, `skin_maps.upsample`), both resampled to the texture's size like
    the skin maps."""
    from .skin_maps import upsample

    if rgb is None:
        rgb, _ = maps.read_image(sp.colour_image, "colour image", key="skin.colour_image")
        mask = maps.read_grey(sp.mask_image, key="skin.mask_image")
    colour = np.stack([cosmetics.image_map(rgb[..., k], height, width, 1.0)
                       for k in range(3)], -1).reshape(-1, 3)[texels]
    mask = cosmetics.image_map(mask, height, width, 1.0).reshape(-1)[texels]
    return {"own_weight": jnp.asarray(1.0 - mask, jnp.float32),
            "own_R": jnp.asarray(upsample(colour, sp.grid), jnp.float32)}


def texture_arrays(sp, height: int, width: int, texels) -> dict:
    """`skin.texture`'s maps (`skin_texture.texture_maps`) as the skin maps' arrays, each
    the fitted value over its scalar's default (so that the scene's scalars, at their
    defaults, give the fitted values, and scale them otherwise), and its mask and colour
    as `own_colour`'s."""
    from .scene import SCHEMA
    from .skin_texture import texture_maps

    t = texture_maps(sp.texture, sp.texture_fixed)
    out = own_colour(sp, height, width, texels, t["colour"], t["skin"])
    for name, map_key in (("melanin", "skin.melanin_fraction_map"),
                          ("haemoglobin", "skin.haemoglobin_map"),
                          ("brightness", "skin.brightness_map")):
        scalar = SKIN_MAPS[map_key][0]
        factor = cosmetics.image_map(t[name] / SCHEMA[scalar].default, height, width, 1.0)
        out[map_cover(map_key)] = jnp.asarray(factor.reshape(-1)[texels], jnp.float32)
    return out


def skin_reflectance(sp, params: dict, arrays: dict, texels=None):
    """The spectral model's skin reflectance on its grid, `(n,)`: the NIST subject darkened
    by `skin.melanin` (`jaxskin.skin`), or the biophysical model (`jaxskin.biophysical`) of
    the `skin.*` parameters (`scene.BIOPHYSICAL_KEYS`). With `texels` (flat indices of the
    texels on the mesh) and a melanin map (`skin.melanin_map` in the params, or the scene's
    `skin.melanin_image`), the NIST skin's melanin varies per texel: `(P, n)`; so do the
    biophysical skin's melanin fraction, haemoglobin and brightness (a factor on its
    reflectance) with theirs (`scene.SKIN_MAPS`)."""
    if sp.skin == "biophysical":
        c = biophysical.Chromophores(*arrays["chromophores"])
        values = {name: params[BIOPHYSICAL_KEYS[name]] for name in biophysical.PARAMS}
        for name in ("melanin", "haemoglobin"):  # per texel with a map: (P,), R (P, n)
            key = f"{BIOPHYSICAL_KEYS[name]}_map"
            factor = None if texels is None else texel_map(params, key, texels,
                                                           arrays.get(map_cover(key)))
            if factor is not None:
                values[name] = values[name] * factor
        if any(jnp.ndim(v) for v in values.values()):
            shape = jnp.broadcast_shapes(*(jnp.shape(v) for v in values.values()))
            values = {k: jnp.broadcast_to(v, shape) for k, v in values.items()}
        R = biophysical.reflectance(c, biophysical.Skin(
            *(values[name] for name in biophysical.PARAMS)))
        # skin.brightness (× its map): a factor on the reflectance (`jaxskin.skin_maps`)
        factor = None if texels is None else texel_map(
            params, "skin.brightness_map", texels, arrays.get(map_cover("skin.brightness_map")))
        brightness = params["skin.brightness"]
        R = R * (brightness if factor is None else brightness * factor)[..., None]
        if "own_R" in arrays and texels is not None:  # skin.mask_image: not skin there
            w = arrays["own_weight"][:, None].astype(R.dtype)
            R = (1.0 - w) * R + w * arrays["own_R"].astype(R.dtype)
        return R
    melanin = params["skin.melanin"]
    factor = None if texels is None else texel_map(params, "skin.melanin_map", texels,
                                                   arrays.get(map_cover("skin.melanin_map")))
    if factor is not None:  # a melanin map: the skin's spectrum per texel, (P, n)
        melanin = melanin * factor[:, None]
    return skin.reflectance(arrays["skin"], melanin, sp.grid)


def map_cover(map_key: str) -> str:
    """The name in `Prepared.arrays` of a skin map loaded from the scene's image
    (`scene.SKIN_MAPS`): per texel on the mesh, `(P,)`."""
    return {"skin.melanin_map": "melanin_cover"}.get(
        map_key, map_key.split(".")[1].removesuffix("_map") + "_cover")


def texel_map(params: dict, key: str, texels, default=None):
    """A per-texel factor for the texels on the mesh, `(P,)`: the texture-space map
    `params[key]` `(H, W)` when the params carry one (a fit's map, `jaxskin.fitting.image`),
    else `default` (the scene's map, from its image or regions; or `None`: no map). A map
    multiplies its scalar, as a scene's image does: `layer.NAME.map` × thickness_mm,
    `skin.melanin_map` × skin.melanin (biophysical: `skin.melanin_fraction_map`,
    `skin.haemoglobin_map`)."""
    value = params.get(key)
    return default if value is None else value.reshape(-1)[texels]
