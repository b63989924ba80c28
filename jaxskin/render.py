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

The cosmetics model (`material.model = "spectral"`, Huang et al. 2013; `"biophysical"`: the
same over the biophysical skin of `jaxskin.biophysical`) shades in texture
space instead, as the paper's SSS needs: irradiance, the Kubelka–Munk layers, the skin
profile's blur over the texture, the highlights (`shading.layered`), then the finished
colour is sampled into the view. No layers: no KM; `sss.enabled = false`: no blur.

Shadows (`light.shadows`, `jaxskin.shadow`): a depth map from the light of the static
configuration decides, once in `prepare`, which points the light reaches: every view
sample for Blinn and Lafortune, every texel for the cosmetics model (so the SSS blur
softens the shadow's edge). The direct light (diffuse and highlight) is multiplied by that
0/1 visibility; ambient light is not. No shadows: no map, nothing traced.

Texture-space images are padded beyond the mesh's texels before the view samples them
(`view.pad_index`): bilinear samples at a silhouette read no background texels.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import cosmetics, maps, shadow, sss, texture
from .precision import matmul
from .raster import interpolate
from .render_args import check_call, check_maps, check_ranges, known_keys, strong
from .samples import list_corners, place, sample_list, to_covered
from .scene import SceneConfig
from .shading import blinn, lafortune, layered
from .skin_texels import skin_arrays, skin_reflectance, texel_map
from .vectors import dot, times3, unit
from .view import (
    PIXEL_TABLE,
    View,
    blend_corners,
    coverage,
    downsample,
    make_view,
    pad_index,
    pixel_table,
    sample_corners,
    sample_padded,
    transpose_table,
    view_pixels,
)

__all__ = ["OUTPUTS", "Prepared", "albedo", "decode_srgb", "encode_srgb", "expose", "prepare",
           "render", "render_prepared", "texture_colour", "texture_to_view"]

OUTPUTS = ("display", "rgba", "linear_rgba")
SHADOW_MAX = 2048  # texels across the shadow map, at most
VIEW_TABLE = ("view_rows", "view_weights", "view_dest")  # `view.transpose_table`
# The cosmetics model's view: `view.pixel_table` (sampling and supersample averaging in one
# linear map, a table each way); a scene without it samples, then averages.
VIEWS = (*VIEW_TABLE, *PIXEL_TABLE)  # every view table (the editor drops them: see there)
# What Blinn and Lafortune read of the bump's fixed maps at the listed samples' corners
# (`corner_arrays`; the editor makes its own for its list)
CORNERS = ("corner_texels", "corner_noise", "corner_mask", "corner_normals", "corner_grad_s",
           "corner_grad_t")


@dataclasses.dataclass(frozen=True, eq=False)
class Prepared:
    """What `prepare` computes once per configuration: the texture-space setup, the camera
    view, the arrays `render_prepared` takes and the texel size on the skin (mm)."""

    setup: texture.TextureSetup
    view: View
    arrays: dict  # what `render` takes as arguments (not as compile-time constants)
    texel_mm: float = 0.0  # the cosmetics model's texel size on the skin (SSS), mm


@functools.lru_cache(maxsize=8)
def prepare(config: SceneConfig) -> Prepared:
    """The host-side work of a configuration, once: mesh, texture space, view, furrows and
    the arrays `render` takes. Evaluated eagerly even when first asked for inside a trace
    (`jit(lambda p: render(config, p))`): staged there, the cache would keep tracers that
    leak into every later call. Only then: under `jax.ensure_compile_time_eval` every
    operation on constants inside the jitted programs it calls (the furrow programs) runs
    and compiles on its own, which made the default hand's `prepare` 6.4–7.1 s instead of
    5.1–5.3 s and the parallel furrow program at 2048² 8.7 s instead of 4.1 s."""
    if not _tracing():
        return _prepare(config)
    with jax.ensure_compile_time_eval():
        return _prepare(config)


def _tracing() -> bool:
    """Whether this call is inside a trace (`jit`, `grad`, ...): there an operation on
    constants is staged, so its result is a tracer."""
    return isinstance(jnp.zeros((), jnp.float32) + 0, jax.core.Tracer)


def _prepare(config: SceneConfig) -> Prepared:
    s = texture.setup(config.texture)
    view = make_view(s.tmap, config.image, config.camera, config.supersample, config.fov,
                     config.rotate, config.image_height, config.zoom, config.center)
    # view_mask: the samples that see the mesh (the alpha); view_shaded: of those, the ones
    # that see a triangle's front (colour is sampled there; the inside of an open mesh,
    # seen through its opening, is black: shaded as the outside, it would be lit from the
    # wrong side)
    # (host arrays by `jax.device_put`: `jnp.asarray` of one compiles a program per shape,
    # which a new process loads from the compilation cache, ~10 ms each)
    arrays = {"normals": s.normals, "mask": s.mask, "tex": jax.device_put(view.tex),
              "view_mask": jax.device_put(view.mask), "view_shaded": jax.device_put(view.shaded),
              "pad": jax.device_put(pad_index(s.tmap.raster.mask, s.tmap.wrap_x).astype(np.int32))}
    # The view sampling's transpose as a table: reverse mode reads it instead of scattering.
    # The cosmetics model samples a colour that is linear all the way to the pixels: the
    # sampling and the averaging over supersamples as one map, a table each way (at
    # 1280x720 the render 152 → 146 ms, its gradient 384 → 344 ms: benchmarks/RESULTS.md).
    if config.spectral is not None and config.mode != "height":
        tables = pixel_table(view.tex, view.shaded, arrays["pad"], s.mask.shape, view.wrap_x,
                             config.supersample)
    elif config.mode != "height":  # Blinn, Lafortune: the samples on the mesh as a list
        tables = sample_list(view.tex, view.shaded, config.supersample)
        tables.update(transpose_table(tables["list_tex"], tables["list_on"], arrays["pad"],
                                      s.mask.shape, view.wrap_x))
        tables["list_corners"] = list_corners(tables["list_tex"], tables["list_on"],
                                              arrays["pad"], s.mask.shape, view.wrap_x)
    else:
        tables = transpose_table(view.tex, view.shaded, arrays["pad"], s.mask.shape,
                                 view.wrap_x)
    arrays.update({k: jax.device_put(v) for k, v in tables.items()})
    if config.needs_furrows:
        arrays["h0"] = texture.furrows(config.texture)[0]
        arrays["noise"] = texture.noise(config.texture)
        arrays.update(s.frame)  # the surface gradients for the general bump form
    if "list_corners" in arrays:
        arrays.update(corner_arrays(s, arrays, arrays["list_corners"]))
    # The camera's rotation (and eye) as arguments: a turn or a zoom in the editor then
    # reuses the compiled program (only the view's arrays change), not compiles a new one.
    arrays["view_R"] = np.asarray(view.R)
    if view.eye is not None:  # perspective: the view direction varies per texel
        arrays["eye"] = np.asarray(view.eye)
        arrays["positions"] = interpolate(s.mesh.vertices.astype(np.float32), s.mesh.faces,
                                          s.tmap.raster)
    sp, texel_mm = config.spectral, 0.0
    if sp is not None:
        grid = sp.grid
        texel_mm = sp.texel_mm or sp.unit_mm * s.tmap.texel_size()
        # The model shades the texels on the mesh only, as a list (the rest stay black).
        texels = np.flatnonzero(np.asarray(s.mask))
        arrays["texels"] = jnp.asarray(texels, jnp.int32)
        if sp.sss == "fft":  # the blur's kernels and edge normalisation: the mask is fixed
            # Arguments, not constants: XLA would fold a constant kernel into the program.
            arrays["sss_kernels"] = jnp.asarray(sss.profile_kernels(texel_mm, s.mask.shape),
                                                jnp.float32)
            arrays["sss_norm"] = jax.jit(sss.mask_norm, static_argnums=1)(
                s.mask.astype(jnp.float32), texel_mm, arrays["sss_kernels"])
        if sp.layers:
            materials = [cosmetics.load_material(layer.material, grid) for layer in sp.layers]
            arrays["S"] = jnp.asarray(np.stack([m.S for m in materials]), jnp.float32)
            arrays["K"] = jnp.asarray(np.stack([m.K for m in materials]), jnp.float32)
            t = s.tmap
            vertex_uv = np.stack([t.xy[:, 0] / t.width, 1.0 - t.xy[:, 1] / t.height], axis=1)
            cover = [cosmetics.coverage(layer, vertex_uv, t.height, t.width, None if
                                        layer.image is None else maps.read_grey(layer.image))
                     for layer in sp.layers]
            arrays["cover"] = jnp.asarray(np.stack(cover).reshape(len(cover), -1)[:, texels],
                                          jnp.float32)
        arrays.update(skin_arrays(sp, s.tmap.height, s.tmap.width, texels))
    if config.shadow is not None and config.mode != "height":
        arrays["lit"] = _visibility(config, s, view)
    return Prepared(s, view, arrays, texel_mm)


def _visibility(config: SceneConfig, s: texture.TextureSetup, view: View):
    """The shadow test (`jaxskin.shadow`) for `config.shadow`'s light, in the object's
    frame: per texel on the mesh `(P,)` for the cosmetics model (the fraction of the
    texel lit), per view sample `(H, W)` otherwise. The map is as fine as the finer of
    texture and view, up to `SHADOW_MAX`."""
    m = s.mesh
    d = np.asarray(config.shadow, np.float64)
    direction = (d / np.linalg.norm(d)) @ view.R  # camera → object frame, as L in `_render`
    size = min(SHADOW_MAX, max(s.tmap.width, s.tmap.height, *view.mask.shape))
    smap = shadow.shadow_map(m.vertices, m.faces, direction, size)
    if config.spectral is not None:
        lit = shadow.texture_visibility(s.tmap, smap)
        return jnp.asarray(lit.reshape(-1)[np.flatnonzero(s.tmap.raster.mask)])
    return jnp.asarray(shadow.visibility(m.vertices, m.faces, m.normals, view.raster, smap))


def render(config: SceneConfig, params: dict, output: str = "display"):
    """The image of a scene, in the params' float dtype (float32 from `load_scene`; float64
    for float64 params under `jax.enable_x64`). `config`, `params`: a scene's
    `Scene.config` and `Scene.params` (keys: `jaxskin.scene`'s differentiable ones, e.g.
    `light.direction (3,)`, `layer.NAME.thickness_mm ()`; per-texel maps such as
    `layer.NAME.map` are `(H, W)` in texture space, the texture's size). A misspelt key, a
    key of a layer the scene has not, or a map of another shape is a `ValueError`; a key the
    scene's model does not use is ignored. A concrete value outside its scene key's range
    (or NaN, or a zero `light.direction`) is a `ValueError` too; traced values (inside your
    jit, grad or vmap) are not checked. `output`: `"display"` `(H, W, 3)` display values
    (clip to [0, 1]) over a black background: the linear image of any material model ×
    2^`camera.exposure`, sRGB-encoded (the height mode: the height itself); `"rgba"`
    `(H, W, 4)` display colour with straight alpha = the mesh's coverage of each pixel
    (PNG's convention); `"linear_rgba"` linear light (exposed) premultiplied by alpha
    (OpenEXR's convention).

    With shadows, a concrete `light.direction` in `params` that differs from the static
    configuration's gets its own shadow map (made here, outside any trace); a traced one
    uses the configuration's (see `jaxskin.shadow`). Calling it inside your own `jit` folds
    the prepared arrays in as constants: use `render_prepared` there."""
    check_call(config, params)
    check_ranges(params, known_keys(config)[0])
    params = strong(params)
    config = _shadow_config(config, params)
    arrays = prepare(config).arrays
    check_maps(params, arrays)
    return _render(config, params, arrays, output)


def corner_arrays(setup: texture.TextureSetup, arrays: dict, corners) -> dict:
    """The fixed maps Blinn and Lafortune read of a bumped scene (one whose `arrays` hold
    the noise) at the listed samples' corners `corners (4, M)` (`samples.list_corners`):
    `texture.corner_inputs`, device arrays (`CORNERS`). {} without a bump (the normals are
    sampled), and where the corners are as many as the texels or more (more samples than
    texels: the default hand's 2 × 2 samples a pixel on a texture as wide as its view),
    for which the whole texture's bump is less work (then sampled, with the same values)."""
    if "noise" not in arrays or np.size(corners) >= np.size(setup.mask):
        return {}
    inputs = texture.corner_inputs(setup, arrays["noise"], np.asarray(corners),
                                   setup.tmap.wrap_x)
    return {k: jax.device_put(v) for k, v in inputs.items()}


def render_prepared(config: SceneConfig, params: dict, arrays: dict,
                    output: str = "display"):
    """`render` with the prepared arrays (`prepare(config).arrays`) passed in: inside your
    own jit, grad or vmap, pass them as arguments, or XLA folds them in as constants."""
    check_call(config, params)
    params = strong(params)
    check_maps(params, arrays)
    return _render(config, params, arrays, output)


def _shadow_config(config: SceneConfig, params: dict) -> SceneConfig:
    d = params.get("light.direction")
    if config.shadow is None or d is None or isinstance(d, jax.core.Tracer):
        return config
    d = np.asarray(d, np.float64)
    old = np.asarray(config.shadow, np.float64)
    if np.allclose(d / np.linalg.norm(d), old / np.linalg.norm(old), rtol=0, atol=1e-7):
        return config
    return dataclasses.replace(config, shadow=tuple(float(c) for c in d))


def _view_table(arrays: dict):
    """The view sampling's transpose table (`VIEW_TABLE`'s arrays), or None without one."""
    return [arrays[k] for k in VIEW_TABLE] if all(k in arrays for k in VIEW_TABLE) else None


@functools.partial(jax.jit, static_argnums=(0, 3))
def _render(config: SceneConfig, params: dict, arrays: dict, output: str = "display"):
    if output not in OUTPUTS:
        raise ValueError(f"output must be one of {OUTPUTS}, got {output!r}")
    # host-side, cached: only texture facts (wrap_x, texel_mm) are read from it; the camera's
    # come in `arrays` (the editor compiles under a key config with another camera)
    p = prepare(config)
    mask, view_mask, k = arrays["mask"], arrays["view_mask"], config.supersample
    shaded = arrays["view_shaded"]

    table = _view_table(arrays)

    def to_view(texture_image):  # bilinear samples at every (super)sample, padded texture
        return sample_padded(texture_image, arrays["pad"], arrays["tex"], shaded,
                             p.view.wrap_x, table)

    def texture_maps():  # the whole texture's height and normals
        if not config.needs_furrows:
            return jnp.ones(mask.shape, jnp.float32), arrays["normals"]
        frame = {k: arrays[k] for k in ("grad_s", "grad_t") if k in arrays}
        maps = texture.bumped(arrays["normals"], mask, arrays["h0"], arrays["noise"], params,
                              frame, p.setup.tmap.wrap_x)
        return maps["height"], maps["normals"]

    if config.mode == "height":  # display values, averaged as they are
        height = texture_maps()[0]
        return _finish(jnp.repeat(to_view(height[..., None]), 3, axis=-1), view_mask, k,
                       output, None)
    if config.spectral is not None:
        normals = texture_maps()[1]
        # linear from texture space to the pixels: sampled and averaged in one map
        mean = texture_to_view(config, arrays, _cosmetics_texture(config, p, params, arrays,
                                                                  normals))
        return _finish(None, view_mask, k, output, params["camera.exposure"], mean)
    # Every material model gives linear sRGB on one scale (`shading.blinn`'s docstring):
    # averaged in linear light, exposed, then encoded.
    # Blinn, Lafortune: shade where the camera looks, the bumped normal map sampled at the
    # view's samples on the mesh (`jaxskin.samples`: fewer than the texels), in the
    # object's frame. Where the samples' bilinear corners are fewer than the texels, the
    # bump is computed at those corner texels only (`texture.bumped_at`, `corner_arrays`):
    # the same normals there, for a quarter of the work at a 1024² texture and 512² view.
    def to_list(texture_image):
        return sample_corners(texture_image, arrays["list_corners"], arrays["list_tex"],
                              arrays["list_on"], table)

    if "corner_texels" in arrays:  # where fewer than the texels (`corner_arrays`)
        N = unit(blend_corners(texture.bumped_at(arrays["h0"], arrays, params),
                               arrays["list_tex"], arrays["list_on"]))
    else:
        N = unit(to_list(texture_maps()[1]))
    L, V = _light_and_view(arrays, params["light.direction"], jnp.float32,
                           lambda: to_list(arrays["positions"]))
    ambient, light = params["light.ambient"], params["light.intensity"]
    if "lit" in arrays:  # shadows: the direct light only where the light reaches
        light = light * arrays["lit"].reshape(-1)[arrays["list_index"]][..., None]
    if config.material == "blinn":
        colour = blinn.shade(N, L, V, params["material.melanin"], params["material.blood"],
                             params["material.specular"], params["material.shininess"],
                             ambient, light)
    else:
        colour = lafortune.shade(params["material.lafortune"], N, L, V, ambient, light)
    colour = jnp.where(arrays["list_on"][..., None], colour, 0.0)
    pixels = (view_mask.shape[0] // k, view_mask.shape[1] // k)
    # the pixels that show a listed sample averaged, exposed and encoded as a list too
    # (the sRGB curve is the frame's costliest step after the bump), then placed
    # (one sample a pixel: the list's rows are the covered pixels', `samples.sample_list`)
    mean = colour if k == 1 else to_covered(colour, arrays)
    tables = {key: arrays[key] for key in ("pixel_covered", "covered_pixel")}

    def place_image(values):
        # Placed in a branch: XLA:CPU would otherwise fuse the shading and the sRGB curve
        # into the gather that places them, computing them once per pixel and channel of
        # the image, in one thread, instead of once per covered pixel (the like-for-like
        # hand of benchmarks/bench_mitsuba.py: 8.1 → 5.7 ms a frame, measured in one run).
        # The other branch, nothing on screen, is the same black image.
        return jax.lax.cond(jnp.any(arrays["list_on"]),
                            lambda v: place(v, tables, pixels),
                            lambda v: jnp.zeros((*pixels, v.shape[-1]), v.dtype), values)
    alpha = None if output == "display" else coverage(view_mask, k)[..., None]
    at_rows = None if alpha is None else jnp.take(alpha.reshape(-1, 1), arrays["covered_pixel"],
                                                   axis=0, mode="fill", fill_value=0.0)
    return _finish_covered(mean, place_image, output, params["camera.exposure"], alpha,
                           at_rows)


def texture_colour(config: SceneConfig, params: dict, arrays: dict, blur_gain=None):
    """The cosmetics model's linear colour in texture space, `(Ht, Wt, 3)` (0 off the
    mesh): what `render_prepared` samples into the view. `texture_to_view` of it, exposed
    and encoded, is the display image (`fitting.image` uses the pair for its per-texel
    Gauss–Newton blocks). `blur_gain (3,)`: the SSS blur's value unchanged, its derivative
    replaced by this gain per channel times the identity (a texel's own share, as
    `fitting.image.blur_gain` sizes it); None: the blur as it is."""
    p = prepare(config)
    if config.needs_furrows:
        frame = {k: arrays[k] for k in ("grad_s", "grad_t") if k in arrays}
        normals = texture.bumped(arrays["normals"], arrays["mask"], arrays["h0"],
                                 arrays["noise"], params, frame, p.setup.tmap.wrap_x)["normals"]
    else:
        normals = arrays["normals"]
    return _cosmetics_texture(config, p, params, arrays, normals, blur_gain)


def texture_to_view(config: SceneConfig, arrays: dict, texture_image):
    """A texture-space image `(Ht, Wt, C)` seen from the camera, linear in it: bilinear
    samples of the padded texture, averaged over each pixel's supersamples, `(H, W, C)`
    (0 where no sample sees the mesh); by `view.pixel_table` where `prepare` made one (the
    cosmetics model), else sampled, then averaged."""
    vm, k = arrays["view_shaded"], config.supersample
    if all(key in arrays for key in PIXEL_TABLE):
        return view_pixels(texture_image, [arrays[key] for key in PIXEL_TABLE],
                           (vm.shape[0] // k, vm.shape[1] // k))
    samples = sample_padded(texture_image, arrays["pad"], arrays["tex"], vm,
                            prepare(config).view.wrap_x, _view_table(arrays))
    return downsample(samples, k)


def _light_and_view(arrays: dict, direction, dtype, positions):
    """Unit light and view directions in the object's frame (where the normals are): L and
    V turned by Rᵀ instead of every normal by R, as N·L = n·RᵀL. The view's rotation R is
    `arrays["view_R"]`. Orthographic: one V; perspective (`arrays["eye"]`): a V per point,
    `positions()` giving the points (object frame)."""
    R = jnp.asarray(arrays["view_R"], dtype)
    L = matmul(direction / jnp.linalg.norm(direction), R)
    if "eye" not in arrays:
        return L, matmul(jnp.asarray([0.0, 0.0, 1.0], dtype), R)
    to_eye = jnp.asarray(arrays["eye"], dtype) - times3(positions(), R.T)  # per point:
    return L, times3(to_eye / jnp.sqrt(dot(to_eye, to_eye, keepdims=True)), R)  # written out


def expose(linear, stops):
    """The camera's exposure: `linear` × 2^`stops` (linear light, before encoding)."""
    return linear * jnp.exp2(jnp.asarray(stops, jnp.result_type(linear)))


def _finish(samples, view_mask, k: int, output: str, stops, averaged=None):
    """Samples `(k H, k W, 3)` (black off the mesh) → the pixels `render` returns. With
    `stops` (the exposure) the samples are linear light: averaged, exposed and encoded;
    `None` (the height mode): display values, averaged as they are (decoded for a linear
    output). `averaged`: the linear samples already averaged (`view_pixels`), for
    `samples`."""
    linear = stops is not None

    def average(samples):  # the samples' average per pixel, or the one given
        return downsample(samples, k) if averaged is None else averaged

    def exposed(image):
        return expose(image, stops) if linear else image

    if output == "display":
        mean = exposed(average(samples))
        return encode_srgb(mean) if linear else mean
    alpha = coverage(view_mask, k)[..., None]
    if output == "linear_rgba":
        mean = exposed(average(samples)) if linear else downsample(
            decode_srgb(samples), k)
        return jnp.concatenate([mean, alpha], axis=-1)
    straight = _straight(exposed(average(samples)), alpha)
    return jnp.concatenate([encode_srgb(straight) if linear else straight, alpha], axis=-1)


def _finish_covered(mean, place_image, output: str, stops, alpha, at_rows):
    """`_finish` of the covered pixels' linear means `mean (P, 3)`, each step on the list,
    then `place_image`d: the same values. `alpha (H, W, 1)` and its values at the rows
    `at_rows (P, 1)` (None for "display"; 0 on the padding rows, which no pixel shows)."""
    mean = expose(mean, stops)
    if output == "display":
        return place_image(encode_srgb(mean))
    if output == "linear_rgba":
        return jnp.concatenate([place_image(mean), alpha], axis=-1)
    return jnp.concatenate([place_image(encode_srgb(_straight(mean, at_rows))), alpha], axis=-1)


def _straight(mean, alpha):
    """Premultiplied `mean` over its coverage `alpha` (straight alpha, as PNG holds it): 0
    where nothing is covered (value and gradient finite there)."""
    covered = alpha > 0
    return jnp.where(covered, mean / jnp.where(covered, alpha, 1.0), 0.0)


def _cosmetics_texture(config: SceneConfig, p: Prepared, params: dict, arrays: dict, normals,
                       blur_gain=None):
    """The cosmetics model's colour in texture space, `(H, W, 3)` (Huang et al. 2013),
    computed on the list of texels on the mesh, `arrays["texels"]` (flat indices)."""
    sp = config.spectral
    mask, texels = arrays["mask"], arrays["texels"]
    shape = mask.shape

    def to_list(image):  # (H, W, C) → (P, C)
        return image.reshape(-1, image.shape[-1])[texels]

    def to_image(values):  # (P, C) → (H, W, C), 0 off the mesh
        out = jnp.zeros((shape[0] * shape[1], values.shape[-1]), values.dtype)
        return out.at[texels].set(values, unique_indices=True).reshape(*shape, -1)

    normals = to_list(normals)
    L, V = _light_and_view(arrays, params["light.direction"], normals.dtype,
                           lambda: to_list(arrays["positions"]))  # per texel
    light = params["light.intensity"]
    if "lit" in arrays:  # shadows, per texel: the blur below softens their edges
        light = light * arrays["lit"]
    blur = None
    if sp.sss is not None:
        def blur(colour):
            out = to_list(sss.blur(to_image(colour), p.texel_mm, mask, sp.sss,
                                   norm=arrays.get("sss_norm"),
                                   kernels=arrays.get("sss_kernels")))
            if blur_gain is None:
                return out
            return jax.lax.stop_gradient(out) + blur_gain * (colour - jax.lax.stop_gradient(
                colour))
    skin_R = skin_reflectance(sp, params, arrays, texels)
    layers = {}
    if sp.layers:
        def per_layer(key):
            return jnp.stack([params[f"layer.{layer.name}.{key}"] for layer in sp.layers])

        cover = jnp.stack([texel_map(params, f"layer.{layer.name}.map", texels,
                                     arrays["cover"][i]) for i, layer in enumerate(sp.layers)])
        if "own_weight" in arrays:  # cosmetics lie on the skin only: the eyes, hair and
            cover = cover * (1.0 - arrays["own_weight"])  # teeth outside the mask take none
        layers = {"S": arrays["S"] * per_layer("s_scale")[:, None],
                  "K": arrays["K"] * per_layer("k_scale")[:, None],
                  "X": cover * per_layer("thickness_mm")[:, None],
                  "roughness": per_layer("roughness"), "rho": per_layer("specular")}
    colour = layered.radiance(sp.grid, normals, L, V, params["light.ambient"], light, skin_R,
                              params["skin.roughness"], params["skin.specular"], blur=blur,
                              **layers)
    return to_image(colour)


def encode_srgb(linear):
    """The sRGB transfer function (IEC 61966-2-1): linear light → display values. Linear
    below 0.0031308 (negative values included), so value and gradient are finite at 0."""
    x = jnp.asarray(linear)
    curved = x > 0.0031308
    power = 1.055 * jnp.where(curved, x, 1.0) ** (1 / 2.4) - 0.055
    return jnp.where(curved, power, 12.92 * x)


def decode_srgb(display):
    """The inverse of `encode_srgb`: display values → linear light (linear below 0.04045,
    negative values included; finite value and gradient at 0)."""
    x = jnp.asarray(display)
    curved = x > 0.04045
    power = ((jnp.where(curved, x, 1.0) + 0.055) / 1.055) ** 2.4
    return jnp.where(curved, power, x / 12.92)


def albedo(config: SceneConfig, params: dict):
    """The diffuse colour a glTF export carries, sRGB-encoded (glTF's base colour): `(3,)`
    for Blinn (the skin albedo) and Lafortune (ρd); for the cosmetics model the texture
    `(H, W, 3)` of the layers over the skin (spectral, no SSS, no highlight)."""
    if config.material == "blinn":
        return encode_srgb(blinn.skin_colour(params["material.melanin"],
                                             params["material.blood"]))
    if config.material == "lafortune":
        return encode_srgb(params["material.lafortune"].diffuse)
    p = prepare(config)
    arrays = p.arrays
    flat = {**params, "light.ambient": jnp.float32(1.0), "light.intensity": jnp.float32(0.0)}
    flat_config = dataclasses.replace(
        config, spectral=dataclasses.replace(config.spectral, sss=None))
    up = jnp.broadcast_to(jnp.asarray([0.0, 0.0, 1.0], jnp.float32), arrays["normals"].shape)
    return encode_srgb(_cosmetics_texture(flat_config, p, flat, arrays, up))
