"""Texture-space maps of a scene: fields, furrow height, bump normals.

`setup(config)` does the static, host-side work once per configuration (mesh, projection,
raster, fields); `furrows(config)` runs the furrow program once per configuration;
`texture_maps(config, params)` is the differentiable part (noise and bump, in JAX). A scene
without wrinkles never calls the furrow program and never traces it.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np

from . import bump, lockstep, wrinkles
from .fields import Edit, interpolate_fields
from .io import InputError
from .mesh import Mesh, load_mesh
from .projection import TextureMap, project
from .raster import interpolate

__all__ = ["EditSpec", "TextureConfig", "TextureSetup", "bumped_at", "corner_inputs", "furrows",
           "mapped", "setup", "texture_maps"]


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
    """What the texture-space maps depend on (the furrows are cached per one of these); a
    scene builds it from its `mesh`, `texture` and `wrinkles` keys (`SceneConfig.texture`)."""

    mesh: str
    projection: str
    size: int
    wrinkles: bool
    k_scale: float
    seed: int
    edits: tuple[EditSpec, ...]
    # The furrow program: "sequential" (wrinkles.height_field) or "parallel"
    # (lockstep.height_field); the scene's "auto" is resolved by `scene.furrow_method`.
    method: str = "sequential"


@dataclasses.dataclass(frozen=True, eq=False)
class TextureSetup:
    """Everything texture space holds for a `TextureConfig`: the mesh, its map to texels,
    the field edits, the vertex and texel direction fields, interpolated normals, the mask
    and (cylindrical, uv) the surface gradients of the texture coordinates."""

    config: TextureConfig
    mesh: Mesh
    tmap: TextureMap
    edits: tuple[Edit, ...]
    d1: np.ndarray  # (V, 3) vertex fields
    d2: np.ndarray
    field1: jax.Array  # (H, W, 2) texture-space fields
    field2: jax.Array
    normals: jax.Array  # (H, W, 3) interpolated unit vertex normals (0 off the mesh)
    mask: jax.Array  # (H, W)
    gradients: tuple | None = None  # (∇s, ∇t) (H, W, 3) each; None for planar (eq. 4.10)

    @property
    def frame(self) -> dict:
        """What `bumped` needs of the surface frame besides the normals (arrays by name)."""
        if self.gradients is None:
            return {}
        return {"grad_s": self.gradients[0], "grad_t": self.gradients[1]}


@functools.lru_cache(maxsize=8)
def setup(config: TextureConfig) -> TextureSetup:
    """The `TextureSetup` of `config`, computed once per configuration (cached): the mesh
    loaded, projected to texture space and rasterized, its field edits interpolated."""
    mesh, tmap = mapped(config.mesh, config.projection, config.size)
    edits = []
    for i, e in enumerate(config.edits):
        if e.vertex is not None:
            if e.vertex >= len(mesh.vertices):
                raise InputError(f"vertex {e.vertex} does not exist; the mesh has "
                                 f"{len(mesh.vertices)} vertices", key=f"fields.edit[{i}].vertex")
            v = e.vertex
        else:
            v = int(np.argmin(np.linalg.norm(mesh.vertices - np.asarray(e.at), axis=1)))
        edits.append(Edit(v, e.d1, e.d2, e.weight))
    d1, d2 = interpolate_fields(mesh, edits)
    raster = tmap.raster
    field1 = interpolate(tmap.vectors(d1).astype(np.float32), mesh.faces, raster)
    field2 = interpolate(tmap.vectors(d2).astype(np.float32), mesh.faces, raster)
    n, gradients = _frame(config.mesh, config.projection, config.size)
    return TextureSetup(config, mesh, tmap, tuple(edits), d1, d2, field1, field2, n,
                        jnp.asarray(raster.mask), gradients)


@functools.lru_cache(maxsize=4)
def mapped(mesh_name: str, projection: str, size: int) -> tuple[Mesh, TextureMap]:
    """The mesh and its texture map (rasterized on first use), shared by every
    configuration that differs only in its field edits (the editor changes those)."""
    mesh = load_mesh(mesh_name)
    try:
        return mesh, project(projection, mesh, size)
    except ValueError as e:
        raise InputError(str(e), key="mesh.projection") from None


@functools.lru_cache(maxsize=4)
def _frame(mesh_name: str, projection: str, size: int):
    """`surface_frame` of `mapped(...)`: like the map, the same for every field edit."""
    return surface_frame(mapped(mesh_name, projection, size)[1])


def surface_frame(tmap: TextureMap):
    """Per texel, the unit normal `(H, W, 3)` and, except for the planar projection (eq.
    4.10 needs neither), the surface gradients (∇s, ∇t) of the texture coordinates
    (`TextureMap.gradients`), interpolated from the vertices; 0 off the mesh."""
    mesh, raster = tmap.mesh, tmap.raster
    n = interpolate(mesh.normals.astype(np.float32), mesh.faces, raster)
    n = n / jnp.maximum(jnp.linalg.norm(n, axis=-1, keepdims=True), 1e-12)
    if tmap.kind == "planar":
        return n, None
    g = tmap.gradients().astype(np.float32)
    return n, tuple(interpolate(g[:, i], mesh.faces, raster) for i in range(2))


RECORDS = 4096


@functools.lru_cache(maxsize=8)
def furrows(config: TextureConfig):
    """The furrow height field before noise, `(H, W)`, and the furrow records, from the
    configuration's furrow program (`config.method`: sequential or parallel)."""
    s = setup(config)
    # The furrow program is an int32/float32 program, not differentiable: the same under
    # a caller's float64 (jax.enable_x64), as in a gradient check of a wrinkled scene.
    with jax.enable_x64(False):
        if config.method == "parallel":
            return lockstep.height_field(
                s.mask, s.field1, s.field2, config.k_scale, jax.random.key(config.seed),
                records=RECORDS, wrap=s.tmap.wrap_x)
        return wrinkles.height_field(
            s.mask, s.field1, s.field2, jnp.asarray(s.tmap.centroids(), jnp.float32),
            config.k_scale, jax.random.key(config.seed),
            radius=wrinkles.window_radius(config.k_scale), records=RECORDS,
            wrap=s.tmap.wrap_x)


def texture_maps(config, params: dict) -> dict:
    """`height (H, W)` and `normals (H, W, 3)` for a scene's static `config` (a
    `scene.SceneConfig`: its `texture` and `needs_furrows`); differentiable in `params`.
    A scene that does not show wrinkles (disabled, or the overview mode) runs no furrows."""
    tex = config.texture
    s = setup(tex)
    if not config.needs_furrows:
        return {"height": jnp.ones(s.mask.shape, jnp.float32), "normals": s.normals}
    h0, _ = furrows(tex)
    return bumped(s.normals, s.mask, h0, noise(tex), params, s.frame, s.tmap.wrap_x)


@functools.lru_cache(maxsize=8)
def noise(config: TextureConfig):
    """The noise field r of step 9 for this configuration's seed (computed once)."""
    return wrinkles.noise_field((setup(config).tmap.height, config.size),
                                jax.random.key(config.seed))


def bumped(normals, mask, h0, r, params, frame: dict, wrap_s: bool = False) -> dict:
    """Noise (step 9) and bump normals on a furrow height field: eq. 4.10 when `frame` is
    empty (planar), else the general form in the surface's frame (`TextureSetup.frame`);
    `wrap_s` (static): s is periodic (a cylinder's texture is exactly one turn wide)."""
    h = wrinkles.add_noise(h0, mask, params["wrinkles.k_noise"], r)
    k = params["wrinkles.k_bump"]
    if not frame:
        return {"height": h, "normals": bump.bump_normals(normals, h, k)}
    return {"height": h, "normals": bump.frame_bump_normals(
        normals, h, k, frame["grad_s"], frame["grad_t"], wrap_s=wrap_s)}


def corner_inputs(setup: TextureSetup, noise, corners, wrap_s: bool = False) -> dict:
    """What `bumped_at` reads of the texture's fixed maps at the texels `corners (4, M)`
    (the listed samples' bilinear corners, `samples.list_corners`), gathered once per view:
    `"corner_texels" (3, 4, M)`, the texels whose heights the forward differences take
    (`bump.difference_texels`), with the noise `"corner_noise"` and the mask
    `"corner_mask"` there; the normals `"corner_normals" (4, M, 3)` and, for the general
    form, the surface gradients `"corner_grad_s"`, `"corner_grad_t"`. `wrap_s`: as
    `bumped`'s."""
    shape = tuple(setup.mask.shape)
    frame = setup.frame
    texels = bump.difference_texels(corners, shape, wrap_s and bool(frame))

    def at(image, index):
        image = np.asarray(image)
        return image.reshape(-1, *image.shape[2:])[index]

    out = {"corner_texels": texels, "corner_noise": at(noise, texels),
           "corner_mask": at(setup.mask, texels), "corner_normals": at(setup.normals, corners)}
    out.update({f"corner_{k}": at(v, corners) for k, v in frame.items()})
    return out


def bumped_at(h0, inputs: dict, params) -> jax.Array:
    """`bumped`'s normals at the texels of `corner_inputs` only, `(4, M, 3)`: noise (step
    9) and eq. 4.10 (or the general form where the inputs hold the surface gradients) with
    the same forward differences, from the height field `h0 (H, W)` read at those texels.
    Blinn and Lafortune sample nothing else of the bump map (`render`)."""
    h = wrinkles.add_noise(jnp.reshape(h0, -1)[inputs["corner_texels"]], inputs["corner_mask"],
                           params["wrinkles.k_noise"], inputs["corner_noise"])
    hs, ht = h[1] - h[0], h[2] - h[0]  # the forward differences of `bump.height_gradient`
    k, n = params["wrinkles.k_bump"], inputs["corner_normals"]
    if "corner_grad_s" not in inputs:
        return bump.tilt(n, hs, ht, k)
    return bump.frame_tilt(n, hs, ht, k, inputs["corner_grad_s"], inputs["corner_grad_t"])
