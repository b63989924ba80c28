"""glTF export: the mesh with its texture mapping, a base-colour and a normal texture.

The base colour is the skin's albedo (Blinn: r_diffuse of eq. 5.7; Lafortune: ρd), not a
lit image, so a glTF viewer's own lights are not applied twice; the wrinkles travel in the
normal texture, in glTF's tangent space (+x along increasing u, +y "up" in the image, +z
the surface normal). The tangent frame of each texel comes from the projection itself
(the world direction of increasing texture x, and of decreasing texture y), made
orthonormal against the interpolated normal, which is what a viewer's MikkTSpace tangents
for these UVs approximate. Vertices are split per face corner so that triangles across
the cylinder's seam keep unwrapped UVs (glTF samplers repeat by default).
"""

from __future__ import annotations

import numpy as np

from .io import atomic_write
from .raster import interpolate

__all__ = ["glb_bytes", "write_glb"]


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0, v / np.maximum(n, 1e-300), 0.0)


def glb_bytes(setup, albedo, normals) -> bytes:
    """A binary glTF of the mesh in `setup` (a `TextureSetup`) with the RGB `albedo` (3,)
    or (H, W, 3) and the bumped world-space `normals (H, W, 3)` of its texture space."""
    import trimesh
    from PIL import Image

    mesh, tmap = setup.mesh, setup.tmap
    H, W = tmap.height, tmap.width
    # Tangent frame per vertex from the projection: rows of the map to texture space.
    T_v = _unit(tmap.vector_map[:, 0, :])
    B_v = _unit(-tmap.vector_map[:, 1, :])  # texture y runs down the image; +y is up
    T = np.asarray(interpolate(T_v.astype(np.float32), mesh.faces, tmap.raster))
    B = np.asarray(interpolate(B_v.astype(np.float32), mesh.faces, tmap.raster))
    n = np.asarray(setup.normals, np.float64)
    T = _unit(T - np.sum(T * n, -1, keepdims=True) * n)
    B = _unit(B - np.sum(B * n, -1, keepdims=True) * n - np.sum(B * T, -1, keepdims=True) * T)
    N = np.asarray(normals, np.float64)
    ts = np.stack([np.sum(N * T, -1), np.sum(N * B, -1), np.sum(N * n, -1)], axis=-1)
    ts = np.where(np.asarray(setup.mask)[..., None], _unit(ts), [0.0, 0.0, 1.0])
    normal_img = np.round((ts * 0.5 + 0.5) * 255).clip(0, 255).astype(np.uint8)
    colour = np.broadcast_to(np.clip(np.asarray(albedo, np.float64), 0, 1), (H, W, 3))
    colour_img = np.round(colour * 255).astype(np.uint8)

    corners = tmap.face_corners()  # (F, 3, 2), unwrapped at a seam
    uv = np.stack([corners[..., 0] / W, corners[..., 1] / H], axis=-1).reshape(-1, 2)
    vertices = mesh.vertices[mesh.faces].reshape(-1, 3)
    faces = np.arange(len(vertices)).reshape(-1, 3)
    material = trimesh.visual.material.PBRMaterial(
        baseColorTexture=Image.fromarray(np.ascontiguousarray(colour_img)),
        normalTexture=Image.fromarray(normal_img), metallicFactor=0.0, roughnessFactor=0.6)
    # glTF's v runs down the image from its top, as our texture y does; trimesh stores v up.
    visual = trimesh.visual.TextureVisuals(uv=np.stack([uv[:, 0], 1 - uv[:, 1]], -1),
                                           material=material)
    out = trimesh.Trimesh(vertices=vertices, faces=faces, visual=visual, process=False)
    return out.export(file_type="glb")


def write_glb(setup, albedo, normals, path) -> None:
    with atomic_write(path, "wb") as fh:
        fh.write(glb_bytes(setup, albedo, normals))
