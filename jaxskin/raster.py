"""One triangle rasterizer for texture space and camera views (the nvdiffrast split).

`rasterize` decides visibility: which triangle covers each pixel centre, and where
(barycentrics). It is not differentiable and runs once per static configuration, on the
host, vectorised over all (triangle, pixel) candidates. `interpolate` is differentiable:
it blends any per-vertex attribute with those barycentrics, in JAX.

Each pixel belongs to at most one triangle: where several cover it (a shared edge, the
two sides of a hand seen through a planar projection), the nearest (smallest `depth`)
wins, then the lowest triangle id, so no texel is ever covered twice.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .precision import einsum

__all__ = ["Raster", "interpolate", "rasterize", "unwrap_seam"]


class Raster(NamedTuple):
    """`tri (H, W)` int32 triangle id (-1: empty) and `bary (H, W, 3)` float32 barycentrics."""

    tri: np.ndarray
    bary: np.ndarray

    @property
    def mask(self) -> np.ndarray:
        """`(H, W)` bool: the pixels or texels a triangle covers."""
        return self.tri >= 0


def rasterize(xy, faces, height: int, width: int, depth=None, wrap_x: bool = False,
              seam=None) -> Raster:
    """Rasterize triangles given in pixel coordinates.

    **Arguments:**

    - `xy (V, 2)`: vertex positions in pixels: x to the right, y down; pixel (i, j) has
      its centre at (j + 0.5, i + 0.5).
    - `faces (F, 3)`: vertex indices.
    - `height`, `width`: image size.
    - `depth (V,)`: optional; where triangles overlap, the smaller interpolated depth wins.
    - `wrap_x`: x is periodic with period `width` (a cylinder cut open): a triangle that
      straddles the cut is drawn across it instead of across the whole image.
    - `seam (F,)`: with `wrap_x`, the triangles that straddle the cut (`unwrap_seam`);
      None: every one wider than half the image.

    **Returns:** a `Raster`.
    """
    xy = np.asarray(xy, np.float64)
    faces = np.asarray(faces, np.int64)
    corners = xy[faces]  # (F, 3, 2)
    if wrap_x and len(faces):
        corners = unwrap_seam(corners, width, seam)
    x0 = np.ceil(corners[..., 0].min(axis=1) - 0.5).astype(np.int64)
    x1 = np.floor(corners[..., 0].max(axis=1) - 0.5).astype(np.int64)
    y0 = np.maximum(np.ceil(corners[..., 1].min(axis=1) - 0.5).astype(np.int64), 0)
    y1 = np.minimum(np.floor(corners[..., 1].max(axis=1) - 0.5).astype(np.int64), height - 1)
    if not wrap_x:
        x0, x1 = np.maximum(x0, 0), np.minimum(x1, width - 1)
    a, b, c = corners[:, 0], corners[:, 1], corners[:, 2]
    area = (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])
    nx, ny = np.maximum(x1 - x0 + 1, 0), np.maximum(y1 - y0 + 1, 0)
    count = np.where(np.abs(area) > 1e-12, nx * ny, 0)

    tri = np.full((height, width), -1, np.int32)
    bary = np.zeros((height, width, 3), np.float32)
    if int(count.sum()) == 0:
        return Raster(tri, bary)
    # The (triangle, pixel) candidates are made and tested CHUNK at a time, and only those
    # inside kept: a 4096² texture of a mesh covering it has ~2 × 4096² candidates, whose
    # dozen float64 temporaries took 6.3 GB at once (measured, a 500k-face UV grid).
    kept = []
    ends = np.searchsorted(np.cumsum(count), np.arange(CHUNK, int(count.sum()), CHUNK))
    for faces_chunk in np.split(np.arange(len(faces)), np.unique(ends)):
        if len(faces_chunk):
            kept.append(_inside(faces_chunk, count, x0, y0, nx, a, b, c, area, width))
    f, px, py, w = (np.concatenate(parts) for parts in zip(*kept, strict=True))
    pixel = py * width + px
    if depth is not None:
        z = (w * np.asarray(depth, np.float64)[faces[f]]).sum(axis=1)
        order = np.lexsort((f, z, pixel))
    else:
        order = np.lexsort((f, pixel))
    pixel, f, w = pixel[order], f[order], w[order]
    first = np.ones(len(pixel), bool)
    first[1:] = pixel[1:] != pixel[:-1]
    tri.reshape(-1)[pixel[first]] = f[first]
    bary.reshape(-1, 3)[pixel[first]] = w[first]
    return Raster(tri, bary)


# Candidates tested at once: about 100 bytes each of temporaries (0.2 GB).
CHUNK = 2_000_000


def _inside(chunk, count, x0, y0, nx, a, b, c, area, width):
    """For the triangles `chunk`, the candidates inside them: triangle, pixel x (wrapped),
    pixel y and barycentrics `(N, 3)`."""
    f = np.repeat(chunk, count[chunk])
    k = np.arange(len(f)) - np.repeat(np.cumsum(count[chunk]) - count[chunk], count[chunk])
    px = x0[f] + k % nx[f]
    py = y0[f] + k // nx[f]
    cx, cy = px + 0.5, py + 0.5
    # Barycentrics from signed areas; inside when all three are >= 0.
    ax, ay, bx, by, qx, qy = a[f, 0], a[f, 1], b[f, 0], b[f, 1], c[f, 0], c[f, 1]
    inv = 1.0 / area[f]
    w0 = ((bx - cx) * (qy - cy) - (by - cy) * (qx - cx)) * inv
    w1 = ((qx - cx) * (ay - cy) - (qy - cy) * (ax - cx)) * inv
    w2 = 1.0 - w0 - w1
    inside = (w0 >= 0) & (w1 >= 0) & (w2 >= 0)
    return f[inside], px[inside] % width, py[inside], np.stack([w0, w1, w2], 1)[inside]


def unwrap_seam(corners, width: int, seam=None) -> np.ndarray:
    """Triangle corners `(F, 3, 2)` in pixels whose x is periodic with period `width` (a
    cylinder cut open): a triangle that straddles the cut has its corners left of the middle
    moved right by `width`. Which triangles straddle it: `seam (F,)` where given (a UV
    map's seam faces: its other faces may span more than half the texture), else every one
    spanning more than half the width (a cylindrical projection's). The one rule the
    rasterizer, the centroids, the camera view and the glTF UVs all use."""
    corners = np.array(corners, np.float64)
    x = corners[..., 0]
    straddle = ((x.max(axis=1) - x.min(axis=1)) > width / 2 if seam is None else
                np.asarray(seam, bool))
    corners[..., 0] = np.where(straddle[:, None] & (x < width / 2), x + width, x)
    return corners


def interpolate(attributes, faces, raster: Raster, empty=0.0):
    """Blend per-vertex `attributes (V, C)` over the raster: `(H, W, C)`, `empty` outside.

    Differentiable with respect to `attributes` (visibility, in `raster`, is fixed).
    """
    # One program (the host arrays go in as arguments): run op by op, each of its dozen
    # operations was a program of its own that a new process loads from the compilation
    # cache (about 10 ms each; a second `jaxskin render hand` ran 25 of them here).
    return _interpolate(attributes, np.asarray(raster.tri), np.asarray(faces),
                        np.asarray(raster.bary), empty)


@jax.jit
def _interpolate(attributes, tri, faces, bary, empty):
    safe = jnp.where(tri >= 0, tri, 0)
    corners = faces[safe]  # (H, W, 3)
    values = attributes[corners]  # (H, W, 3, C)
    out = einsum("hwk,hwkc->hwc", bary.astype(values.dtype), values)
    return jnp.where((tri >= 0)[..., None], out, jnp.asarray(empty, out.dtype))
