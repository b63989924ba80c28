"""`render(config, params) -> image`: the pure function behind the CLI, sweeps and gradients.

The static configuration (a `SceneConfig`: which stages run, sizes, mesh, camera) decides
what is traced; the parameters (a dict of arrays: melanin, blood, light, lobes, k_bump …)
are what is differentiable. Host-side work — mesh, projection, fields, rasterization of
texture space and of the view, the furrows — happens once per configuration (`prepare`);
`render` then computes the bumped normal map in texture space (§4.1), samples it into
the view (bilinear) and shades there (§4.2): the paper lights every texel of the texture,
we light the texels the camera sees, which is the same map read at the same places.
Stages a scene does not use are not traced: no furrows without wrinkles
or in the overview mode, no Lafortune code in a Blinn scene and the reverse.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import texture
from .raster import interpolate
from .scene import SceneConfig
from .shading import blinn, lafortune
from .view import View, downsample, make_view, sample

__all__ = ["Prepared", "prepare", "render", "render_prepared"]


@dataclasses.dataclass(frozen=True, eq=False)
class Prepared:
    setup: texture.TextureSetup
    view: View
    arrays: dict  # what `render` takes as arguments (not as compile-time constants)


@functools.lru_cache(maxsize=8)
def prepare(config: SceneConfig) -> Prepared:
    s = texture.setup(config.texture)
    view = make_view(s.tmap, config.image, config.camera, config.supersample, config.fov,
                     config.rotate)
    arrays = {"normals": s.normals, "mask": s.mask, "tex": jnp.asarray(view.tex),
              "view_mask": jnp.asarray(view.mask)}
    if config.needs_furrows:
        arrays["h0"] = texture.furrows(config.texture)[0]
        arrays["noise"] = texture.noise(config.texture)
    if view.eye is not None:  # perspective: the view direction varies per texel
        arrays["positions"] = interpolate(s.mesh.vertices.astype(np.float32), s.mesh.faces,
                                          s.tmap.raster)
    return Prepared(s, view, arrays)


def render(config: SceneConfig, params: dict):
    """The image `(size, size, 3)` of a scene, float32, display values (clip to [0, 1])."""
    return _render(config, params, prepare(config).arrays)


def render_prepared(config: SceneConfig, params: dict, arrays: dict):
    """`render` with the prepared arrays (`prepare(config).arrays`) passed in: inside your
    own jit, grad or vmap, pass them as arguments, or XLA folds them in as constants."""
    return _render(config, params, arrays)


@functools.partial(jax.jit, static_argnums=0)
def _render(config: SceneConfig, params: dict, arrays: dict):
    p = prepare(config)  # host-side, cached: only static facts (rotation, eye) are used
    mask, view_mask, k = arrays["mask"], arrays["view_mask"], config.supersample

    def to_view(texture_image):  # bilinear samples at every (super)sample
        return sample(texture_image, arrays["tex"], view_mask, p.view.wrap_x)

    if config.needs_furrows:
        maps = texture.bumped(arrays["normals"], mask, arrays["h0"], arrays["noise"], params)
        height, normals = maps["height"], maps["normals"]
    else:
        height, normals = jnp.ones(mask.shape, jnp.float32), arrays["normals"]
    if config.mode == "height":
        colour = jnp.repeat(to_view(height[..., None]), 3, axis=-1)
    else:
        # Shade where the camera looks: the bumped normal map sampled into the view (fewer
        # samples than texels), in the object's frame (L and V turned by Rᵀ instead of
        # every normal by R: N·L = n·RᵀL).
        n = to_view(normals)
        nn = jnp.sum(n * n, axis=-1, keepdims=True)
        N = jnp.where(nn > 0, n / jnp.sqrt(jnp.where(nn > 0, nn, 1.0)), 0.0)
        R = jnp.asarray(p.view.R, jnp.float32)
        d = params["light.direction"]
        L = (d / jnp.linalg.norm(d)) @ R
        if p.view.eye is None:
            V = jnp.asarray([0.0, 0.0, 1.0], jnp.float32) @ R
        else:
            to_eye = jnp.asarray(p.view.eye, jnp.float32) - to_view(arrays["positions"]) @ R.T
            V = (to_eye / jnp.linalg.norm(to_eye, axis=-1, keepdims=True)) @ R
        ambient, light = params["light.ambient"], params["light.intensity"]
        if config.material == "blinn":
            colour = blinn.shade(N, L, V, params["material.melanin"], params["material.blood"],
                                 params["material.specular"], params["material.shininess"],
                                 ambient, light)
        else:
            colour = lafortune.shade(params["material.lafortune"], N, L, V, ambient, light)
        colour = jnp.where(view_mask[..., None], colour, 0.0)
    return downsample(colour, k)
