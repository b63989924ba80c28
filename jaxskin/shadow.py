"""Shadows of a parallel light: a depth map along the light, made by the project's rasterizer.

The mesh is seen from the light (an orthographic view along it, nvdiffrast's split as for
the camera): `shadow_map` keeps, per shadow texel, the depth of the surface nearest to the
light; `lit` tells whether points of the surface are that nearest surface (lit) or lie
behind it (in shadow), with a bias that grows with the slope of the surface to the light
(a texel of a tilted plane spans a range of depths). Both run on the host, once per static
configuration: visibility is piecewise constant, like the rasterizer's, and what the
renderer does with it (multiply the direct light) stays differentiable.

The light direction is a differentiable parameter (`light.direction`); the shadow test uses
the direction of the static configuration (`SceneConfig.shadow`), so the gradient with
respect to the light direction ignores the moving shadow edge (as it ignores moving
silhouettes). `render.render` called with a concrete direction that differs makes the map
for that direction (outside the traced function).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from .raster import Raster, rasterize

__all__ = ["BIAS", "MAX_SLOPE", "SUBTEXEL", "ShadowMap", "light_frame", "lit", "shadow_map",
           "texture_visibility", "visibility"]

MARGIN = 0.02  # of the shadow map, around the mesh
BIAS = 1.5  # shadow texels of constant depth bias
SUBTEXEL = 2  # shadow tests per texel and axis in texture space (a fractional edge)
MAX_SLOPE = 8.0  # the slope bias stops growing at grazing light (N·L ≈ 0.12; unlit anyway)


class ShadowMap(NamedTuple):
    """`depth (S, S)`: distance from the light plane to the nearest surface, in mesh units
    (inf where no surface); `frame (3, 3)`: rows u, v (the map's x, y) and w (toward the
    light); `centre (2,)` in (u, v) and `scale` (texels per mesh unit) place the map."""

    depth: np.ndarray
    frame: np.ndarray
    centre: np.ndarray
    scale: float

    def to_pixels(self, points) -> tuple[np.ndarray, np.ndarray]:
        """Map coordinates `(..., 2)` in texels (x right, y down) and depth `(...)` of
        `points (..., 3)`."""
        q = np.asarray(points, np.float64) @ self.frame.T
        size = self.depth.shape[0]
        xy = np.stack([(q[..., 0] - self.centre[0]) * self.scale + size / 2,
                       size / 2 - (q[..., 1] - self.centre[1]) * self.scale], axis=-1)
        return xy, -q[..., 2]


def light_frame(direction) -> np.ndarray:
    """An orthonormal frame `(3, 3)`, rows u, v, w, with w the unit `direction` (toward the
    light) and u, v spanning the plane the map lies in (right-handed)."""
    w = np.asarray(direction, np.float64)
    w = w / np.linalg.norm(w)
    helper = np.array([0.0, 1.0, 0.0]) if abs(w[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(helper, w)
    u /= np.linalg.norm(u)
    return np.stack([u, np.cross(w, u), w])


def shadow_map(vertices, faces, direction, size: int) -> ShadowMap:
    """The depth map of the mesh `vertices (V, 3)`, `faces (F, 3)` seen from a parallel
    light toward `direction` (the mesh's frame), `size` texels square."""
    frame = light_frame(direction)
    q = np.asarray(vertices, np.float64) @ frame.T
    lo, hi = q[:, :2].min(axis=0), q[:, :2].max(axis=0)
    scale = size * (1 - 2 * MARGIN) / max(float(np.max(hi - lo)), 1e-300)
    smap = ShadowMap(np.zeros((size, size)), frame, (lo + hi) / 2, scale)
    xy, depth = smap.to_pixels(vertices)
    r = rasterize(xy, faces, size, size, depth=depth)
    safe = np.where(r.tri >= 0, r.tri, 0)
    d = np.einsum("hwk,hwk->hw", r.bary.astype(np.float64), depth[np.asarray(faces)[safe]])
    return smap._replace(depth=np.where(r.mask, d, np.inf))


def lit(smap: ShadowMap, points, normals) -> np.ndarray:
    """Whether each of `points (..., 3)` (on the surface, with unit `normals (..., 3)`) is
    the surface nearest to the light at its shadow texel: `(...)` bool. Points outside
    the map are lit. The bias, in texels of depth, is `BIAS` + the surface's slope to the
    light (tan of the angle between normal and light, up to `MAX_SLOPE`): a texel centre
    lies up to √2/2 texel from the point, where a tilted plane's depth differs by that
    distance × the slope."""
    xy, depth = smap.to_pixels(points)
    size = smap.depth.shape[0]
    ix, iy = np.floor(xy[..., 0]).astype(np.int64), np.floor(xy[..., 1]).astype(np.int64)
    inside = (ix >= 0) & (ix < size) & (iy >= 0) & (iy < size)
    nearest = smap.depth[np.clip(iy, 0, size - 1), np.clip(ix, 0, size - 1)]
    cos = np.abs(np.asarray(normals, np.float64) @ smap.frame[2])
    slope = np.sqrt(np.maximum(1 - cos * cos, 0.0)) / np.maximum(cos, 1.0 / MAX_SLOPE)
    bias = (BIAS + np.minimum(slope, MAX_SLOPE)) / smap.scale
    return ~inside | (depth <= nearest + bias)


def visibility(vertices, faces, normals, raster: Raster, smap: ShadowMap) -> np.ndarray:
    """`lit` at the surface points a raster sees (texture space or a camera view): `(H, W)`
    float32, 1 lit, 0 in shadow (and 1 where the raster sees no surface).

    A coarse mesh shaded with smooth `normals (V, 3)` is lit where its flat triangles
    are not (the shadow terminator problem: blocky shadows on the lit side of a curve).
    As in Hanika (2021, "Hacking the shadow terminator"), each point is tested where the
    smooth surface would be, not on its flat triangle: the barycentric blend of its
    projections onto the vertices' tangent planes, where that lies outside (convex
    parts); the slope bias uses the flat triangle's normal, whose depth the map holds."""
    vertices = np.asarray(vertices, np.float64)
    faces = np.asarray(faces)
    safe = np.where(raster.tri >= 0, raster.tri, 0)
    corners = faces[safe]  # (H, W, 3)
    bary = raster.bary.astype(np.float64)[..., None]
    v = vertices[corners]  # (H, W, 3, 3)
    n = np.asarray(normals, np.float64)[corners]
    points = (bary * v).sum(axis=-2)
    a, b, c = (vertices[faces[:, i]] for i in range(3))
    flat = np.cross(b - a, c - a)
    flat = (flat / np.maximum(np.linalg.norm(flat, axis=1, keepdims=True), 1e-300))[safe]
    to_plane = np.sum((points[..., None, :] - v) * n, axis=-1, keepdims=True)
    smooth = (bary * (points[..., None, :] - to_plane * n)).sum(axis=-2)
    outside = np.sum((smooth - points) * flat, axis=-1, keepdims=True) > 0
    points = np.where(outside, smooth, points)
    return np.where(raster.mask, lit(smap, points, flat), True).astype(np.float32)


def texture_visibility(tmap, smap: ShadowMap, k: int | None = None) -> np.ndarray:
    """The fraction of each texel of `tmap` (a `projection.TextureMap`) that the light
    reaches: `(H, W)` float32, from k × k tests per texel (texture space rasterized k
    times finer), so the shadow's edge is not a staircase of whole texels; 1 off the
    mesh. `k`: `SUBTEXEL`, or 1 for textures over 1024² texels (host memory)."""
    if k is None:
        k = SUBTEXEL if tmap.width * tmap.height <= 1024 * 1024 else 1
    mesh = tmap.mesh
    fine = rasterize(np.asarray(tmap.xy) * k, mesh.faces, tmap.height * k, tmap.width * k,
                     tmap.depth, tmap.wrap_x)
    lit_fine = visibility(mesh.vertices, mesh.faces, mesh.normals, fine, smap)
    H, W = tmap.height, tmap.width
    covered = fine.mask.reshape(H, k, W, k).sum(axis=(1, 3))
    reached = (lit_fine * fine.mask).reshape(H, k, W, k).sum(axis=(1, 3))
    return np.where(covered > 0, reached / np.maximum(covered, 1), 1.0).astype(np.float32)
