"""glTF export: the mesh with smooth normals, tangents, its texture mapping, a base-colour
and a normal texture, as one binary glTF (GLB) written here (glTF 2.0, no library between).

The base colour is the skin's albedo (Blinn: r_diffuse of eq. 5.7; Lafortune: ρd; the
cosmetics model: the layers over the skin), not a lit image, so a glTF viewer's own lights
are not applied twice; the wrinkles travel in the normal texture, in glTF's tangent space
(+x along increasing u, +y "up" = decreasing v, +z the surface normal).

Each vertex carries the mesh's smooth (area-weighted) normal and a tangent in the manner
of MikkTSpace: per triangle, the directions of increasing u and of decreasing v on the
surface (from its positions and UVs), summed over the triangles round the vertex, the
tangent made orthogonal to the normal, and w = ±1 the handedness of (normal, tangent,
up). The normal texture is baked in the frame a viewer rebuilds from these attributes
(interpolated normal and tangent, bitangent = cross(n, t) w), so what the viewer shows is
the bumped normal the renderer used. Vertices are split where a vertex has two UVs (the
cylinder's seam: its triangles keep unwrapped UVs, u > 1, with a repeating sampler), and
both textures are padded beyond the mesh's texels so that viewers' filtering and
mipmaps read no background at the UV islands' edges.
"""

from __future__ import annotations

import json
import struct

import numpy as np

from . import __version__
from .io import atomic_write
from .raster import interpolate
from .view import pad_index

__all__ = ["PAD_TEXELS", "glb_bytes", "read_glb", "vertex_tangents", "write_glb"]

PAD_TEXELS = 8  # texture padding beyond the mesh (mipmap levels down to 1/8 stay clean)
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
FLOAT, UNSIGNED_INT = 5126, 5125


def _unit(v):
    n = np.linalg.norm(v, axis=-1, keepdims=True)
    return np.where(n > 0, v / np.maximum(n, 1e-300), 0.0)


def vertex_tangents(vertices, faces, corner_uv, normals) -> np.ndarray:
    """Tangents `(V, 4)`: xyz the unit direction of increasing u, orthogonal to the unit
    `normals (V, 3)`, w = ±1 the handedness (+1 where cross(normal, tangent) points to
    decreasing v, glTF's "up" in the image). `corner_uv (F, 3, 2)`: the UV of each
    triangle corner (v down, as glTF). Triangles with no UV area add nothing; a vertex
    with none gets any unit tangent orthogonal to its normal."""
    p = np.asarray(vertices, np.float64)[faces]  # (F, 3, 3)
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    d1, d2 = corner_uv[:, 1] - corner_uv[:, 0], corner_uv[:, 2] - corner_uv[:, 0]
    det = d1[:, 0] * d2[:, 1] - d2[:, 0] * d1[:, 1]
    ok = np.abs(det) > 1e-12
    r = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)[:, None]
    # Solve [e1 e2] = [dP/du dP/dv] [d1 d2] for the surface derivatives.
    dpdu = (e1 * d2[:, 1:2] - e2 * d1[:, 1:2]) * r
    dpdv = (e2 * d1[:, 0:1] - e1 * d2[:, 0:1]) * r
    # Weighted by the triangle's area (|e1 × e2|/2 = |det| × |dP/du × dP/dv|/2: the
    # unnormalised derivatives times |det| carry it).
    area = np.abs(det)[:, None]
    T = np.zeros((len(vertices), 3))
    U = np.zeros((len(vertices), 3))
    for i in range(3):
        np.add.at(T, faces[:, i], dpdu * area)
        np.add.at(U, faces[:, i], -dpdv * area)  # "up" = decreasing v
    n = _unit(np.asarray(normals, np.float64))
    t = T - np.sum(T * n, -1, keepdims=True) * n
    length = np.linalg.norm(t, axis=-1, keepdims=True)
    helper = np.where(np.abs(n[:, :1]) < 0.9, [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    fallback = _unit(np.cross(n, helper))
    t = np.where(length > 1e-12 * np.maximum(np.linalg.norm(T, axis=-1, keepdims=True), 1e-300),
                 t / np.maximum(length, 1e-300), fallback)
    w = np.where(np.sum(np.cross(n, t) * U, axis=-1) < 0, -1.0, 1.0)
    return np.concatenate([t, w[:, None]], axis=1)


def _bake_normals(setup, tangents, normals):
    """The bumped world-space `normals (H, W, 3)` in the tangent frame a viewer rebuilds
    per texel from the vertex normals and `tangents (V, 4)`: `(H, W, 3)` unit."""
    mesh, raster = setup.mesh, setup.tmap.raster
    n = np.asarray(setup.normals, np.float64)
    t = np.asarray(interpolate(tangents[:, :3].astype(np.float32), mesh.faces, raster),
                   np.float64)
    w = np.asarray(interpolate(tangents[:, 3:].astype(np.float32), mesh.faces, raster))[..., 0]
    t = _unit(t - np.sum(t * n, -1, keepdims=True) * n)
    b = np.cross(n, t) * np.where(w < 0, -1.0, 1.0)[..., None]
    N = np.asarray(normals, np.float64)
    ts = np.stack([np.sum(N * t, -1), np.sum(N * b, -1), np.sum(N * n, -1)], axis=-1)
    return np.where(np.asarray(raster.mask)[..., None], _unit(ts), [0.0, 0.0, 1.0])


def glb_bytes(setup, albedo, normals) -> bytes:
    """A binary glTF of the mesh in `setup` (a `TextureSetup`) with the RGB `albedo` (3,)
    or (H, W, 3) and the bumped world-space `normals (H, W, 3)` of its texture space."""
    from .maps import png_bytes

    mesh, tmap = setup.mesh, setup.tmap
    H, W = tmap.height, tmap.width
    corners = tmap.face_corners()  # (F, 3, 2) pixels, unwrapped at a seam
    corner_uv = corners / np.array([W, H], np.float64)  # glTF: u right, v down the image
    tangents = vertex_tangents(mesh.vertices, mesh.faces, corner_uv, mesh.normals)

    # One glTF vertex per (mesh vertex, UV): split only where a vertex has two UVs.
    keys = np.concatenate([mesh.faces.reshape(-1, 1).astype(np.float64),
                           corner_uv.reshape(-1, 2)], axis=1)
    unique, inverse = np.unique(keys, axis=0, return_inverse=True)
    source = unique[:, 0].astype(np.int64)
    positions = mesh.vertices[source].astype(np.float32)
    vertex_normals = _unit(mesh.normals[source]).astype(np.float32)
    vertex_normals /= np.linalg.norm(vertex_normals, axis=1, keepdims=True)  # unit in f32
    vertex_tangents_ = tangents[source].astype(np.float32)
    vertex_tangents_[:, :3] /= np.linalg.norm(vertex_tangents_[:, :3], axis=1, keepdims=True)
    uv = unique[:, 1:].astype(np.float32)
    indices = inverse.reshape(-1).astype(np.uint32)

    pad = pad_index(tmap.raster.mask, tmap.wrap_x, PAD_TEXELS)
    ts = _bake_normals(setup, tangents, normals).reshape(-1, 3)[pad]
    normal_img = np.round((ts * 0.5 + 0.5) * 255).clip(0, 255).astype(np.uint8)
    colour = np.broadcast_to(np.clip(np.asarray(albedo, np.float64), 0, 1), (H, W, 3))
    colour_img = np.round(colour.reshape(-1, 3)[pad] * 255).astype(np.uint8).reshape(H, W, 3)

    gltf = {
        "asset": {"version": "2.0", "generator": f"jaxskin {__version__}"},
        "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0, "name": mesh.name}],
        "meshes": [{"name": mesh.name, "primitives": [{
            "attributes": {"POSITION": 1, "NORMAL": 2, "TANGENT": 3, "TEXCOORD_0": 4},
            "indices": 0, "material": 0, "mode": 4}]}],
        "materials": [{"name": "skin", "pbrMetallicRoughness": {
            "baseColorTexture": {"index": 0}, "metallicFactor": 0.0, "roughnessFactor": 0.6},
            "normalTexture": {"index": 1}}],
        # u repeats (a cylinder's unwrapped seam reaches past 1), v does not.
        "samplers": [{"magFilter": 9729, "minFilter": 9987, "wrapS": 10497, "wrapT": 33071}],
        "textures": [{"sampler": 0, "source": 0}, {"sampler": 0, "source": 1}],
        "images": [], "accessors": [], "bufferViews": [], "buffers": [],
    }
    blob = bytearray()

    def view(data: bytes, target=None) -> int:
        blob.extend(b"\0" * (-len(blob) % 4))  # every view starts 4-byte aligned
        entry = {"buffer": 0, "byteOffset": len(blob), "byteLength": len(data)}
        if target is not None:
            entry["target"] = target
        blob.extend(data)
        gltf["bufferViews"].append(entry)
        return len(gltf["bufferViews"]) - 1

    def accessor(array, kind, component, target, bounds=False):
        entry = {"bufferView": view(np.ascontiguousarray(array).tobytes(), target),
                 "componentType": component, "count": int(len(array)), "type": kind}
        if bounds:
            entry["min"] = np.asarray(array.min(axis=0)).reshape(-1).tolist()
            entry["max"] = np.asarray(array.max(axis=0)).reshape(-1).tolist()
        gltf["accessors"].append(entry)

    accessor(indices, "SCALAR", UNSIGNED_INT, ELEMENT_ARRAY_BUFFER)
    accessor(positions, "VEC3", FLOAT, ARRAY_BUFFER, bounds=True)
    accessor(vertex_normals, "VEC3", FLOAT, ARRAY_BUFFER)
    accessor(vertex_tangents_, "VEC4", FLOAT, ARRAY_BUFFER)
    accessor(uv, "VEC2", FLOAT, ARRAY_BUFFER)
    for image in (colour_img, normal_img):
        gltf["images"].append({"bufferView": view(png_bytes(image)), "mimeType": "image/png"})
    blob.extend(b"\0" * (-len(blob) % 4))
    gltf["buffers"].append({"byteLength": len(blob)})
    text = json.dumps(gltf, separators=(",", ":")).encode()
    text += b" " * (-len(text) % 4)
    total = 12 + 8 + len(text) + 8 + len(blob)
    return b"".join([struct.pack("<4sII", b"glTF", 2, total),
                     struct.pack("<I4s", len(text), b"JSON"), text,
                     struct.pack("<I4s", len(blob), b"BIN\0"), bytes(blob)])


def read_glb(data: bytes) -> tuple[dict, bytes]:
    """The JSON and the binary chunk of a GLB (as `glb_bytes` writes: one of each)."""
    magic, version, total = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2 or total != len(data):
        raise ValueError("not a glTF 2.0 binary")
    n, kind = struct.unpack_from("<I4s", data, 12)
    if kind != b"JSON":
        raise ValueError("the first chunk of a GLB must be JSON")
    doc = json.loads(data[20:20 + n])
    m, kind = struct.unpack_from("<I4s", data, 20 + n)
    if kind != b"BIN\0":
        raise ValueError("the second chunk of a GLB must be BIN")
    return doc, data[28 + n:28 + n + m]


def write_glb(setup, albedo, normals, path) -> None:
    """Write `glb_bytes(setup, albedo, normals)` to `path` atomically."""
    with atomic_write(path, "wb") as fh:
        fh.write(glb_bytes(setup, albedo, normals))
