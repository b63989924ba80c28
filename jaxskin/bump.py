"""Bump-mapped normals in texture space (Bando 2001 §4.1, eq. 4.2 and 4.9–4.11).

Blinn's bump mapping displaces the surface P(s, t) by k h along its unit normal n; to first
order in k the normal of P + k h n is (eq. 4.2, with the paper's k_bump)

    N' = N + k ∂h/∂s (n × P_t) + k ∂h/∂t (P_s × n),     N = P_s × P_t.

Divided by N·n this is n − k (∂h/∂s ∇s + ∂h/∂t ∇t): the normal tilts against the surface
gradient of h, where ∇s, ∇t (the surface gradients of the texture coordinates, the dual
basis of P_s, P_t in the tangent plane) come from the projection and the mesh
(`TextureMap.gradients`, interpolated per texel and made orthogonal to n here). That
**general form** (`frame_bump_normals`) is what every projection uses except the planar
one. Nothing divides: |n − k g| >= 1 for a unit n and tangential g, so it is finite at any
angle, n_z → 0 included.

**Planar projection: eq. 4.10 exactly** (`bump_normals`). There s, t are the object's x, y,
so ∇s = (1, 0, 0) − n_x n and ∇t = (0, 1, 0) − n_y n, and the general form becomes

    N'' = n + k_bump ∂h/∂s (n × (0, n_z, −n_y)) + k_bump ∂h/∂t ((n_z, 0, −n_x) × n)

identically, since n × (0, n_z, −n_y) = n_x n − (1, 0, 0) and (n_z, 0, −n_x) × n =
n_y n − (0, 1, 0) for |n| = 1 (tests/test_bump_frames.py checks it numerically). It is the
paper's form after multiplying through by n_z; the sides of a planar projection (n_z → 0),
where one texel spans a long stretch of surface, stretch the pattern: the paper's known
limitation (figs. 6.1(f), 6.2(f)), kept as it is. With the cylindrical projection eq. 4.10
would tilt normals along x whatever the angle round the axis, so furrows turned to ridges
on the back; hence the general form there and for `uv`.

Derivatives of h are forward differences in texels (eq. 4.11; Δs = Δt = one texel, t up,
i.e. to the previous row); with `wrap_s` (a cylinder) s is periodic, so the last column
differences with the first. Off the mesh (n = 0) a double `where` returns 0 with zero
gradient.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .vectors import dot, unit_stack

__all__ = ["bump_normals", "difference_texels", "frame_bump_normals", "frame_tilt",
           "height_gradient", "tilt"]


def height_gradient(h: Float[ArrayLike, "H W"], wrap_s: bool = False) -> tuple[Array, Array]:
    """(∂h/∂s, ∂h/∂t) by forward differences in texels (eq. 4.11): ∂h/∂t is 0 on the first
    row (t up: it differences with the previous row), ∂h/∂s on the last column unless
    `wrap_s` (periodic s: it differences with the first column)."""
    h = jnp.asarray(h)
    if wrap_s:
        hs = jnp.roll(h, -1, axis=1) - h
    else:
        hs = jnp.pad(h[:, 1:] - h[:, :-1], ((0, 0), (0, 1)))
    ht = jnp.pad(h[:-1, :] - h[1:, :], ((1, 0), (0, 0)))  # t up: row r − 1 is t + Δt
    return hs, ht


def difference_texels(texels, shape: tuple[int, int], wrap_s: bool = False) -> np.ndarray:
    """The texels `height_gradient` differences at `texels` (flat indices into a texture of
    `shape`, any array shape): `(3, *texels.shape)` int32 flat indices of the texel, its
    neighbour along s (the next column) and its neighbour along t (the previous row); where
    `height_gradient` gives 0 (the last column unless `wrap_s`, the first row), the texel
    itself, so that the difference is 0 there too."""
    H, W = shape
    texels = np.asarray(texels, np.int64)
    row, col = texels // W, texels % W
    if wrap_s:
        s = row * W + (col + 1) % W
    else:
        s = np.where(col < W - 1, texels + 1, texels)
    t = np.where(row > 0, texels - W, texels)
    return np.stack([texels, s, t]).astype(np.int32)


def bump_normals(
    normals: Float[ArrayLike, "H W 3"], h: Float[ArrayLike, "H W"], k_bump
) -> Float[Array, "H W 3"]:
    """Eq. 4.10: perturbed unit normals `(H, W, 3)` for the **planar** projection, from the
    interpolated normal map and the height field. Differentiable in all three."""
    return tilt(normals, *height_gradient(h), k_bump)


def tilt(normals: Float[ArrayLike, "... 3"], hs, ht, k_bump) -> Float[Array, "... 3"]:
    """Eq. 4.10 at each point (`bump_normals` without the differences): the unit normal of
    `normals (..., 3)` tilted by the height's forward differences `hs`, `ht (...)`. The
    renderer evaluates it at the texels its view reads only (`texture.bumped_at`)."""
    n = jnp.asarray(normals)
    nx, ny, nz = n[..., 0], n[..., 1], n[..., 2]
    # n × (0, n_z, −n_y) and (n_z, 0, −n_x) × n, as `jnp.cross` writes them, component by
    # component: XLA:CPU runs the stacked (..., 3) form 4x slower (`jaxskin.vectors`)
    a = (ny * -ny - nz * nz, nz * 0.0 - nx * -ny, nx * nz - ny * 0.0)
    b = (0.0 * nz - -nx * ny, -nx * nx - nz * nz, nz * ny - 0.0 * nx)
    return unit_stack([n[..., i] + k_bump * (hs * a[i] + ht * b[i]) for i in range(3)])


def frame_bump_normals(
    normals: Float[ArrayLike, "H W 3"], h: Float[ArrayLike, "H W"], k_bump,
    grad_s: Float[ArrayLike, "H W 3"], grad_t: Float[ArrayLike, "H W 3"], wrap_s: bool = False,
) -> Float[Array, "H W 3"]:
    """The general form, n' = normalize(n − k (∂h/∂s ∇s' + ∂h/∂t ∇t')), for any projection.

    **Arguments:**

    - `normals (H, W, 3)`: the interpolated unit normal map (0 off the mesh).
    - `h (H, W)`: the height field; `k_bump`: the paper's scale.
    - `grad_s`, `grad_t (H, W, 3)`: the surface gradients of s and t per texel
      (`TextureMap.gradients` interpolated); their parts along n are removed here (∇s').
    - `wrap_s`: s is periodic (the cylindrical projection's seam).

    **Returns:** unit normals `(H, W, 3)`, 0 off the mesh. Differentiable in every array.
    """
    return frame_tilt(normals, *height_gradient(h, wrap_s), k_bump, grad_s, grad_t)


def frame_tilt(normals: Float[ArrayLike, "... 3"], hs, ht, k_bump, grad_s, grad_t
               ) -> Float[Array, "... 3"]:
    """The general form at each point (`frame_bump_normals` without the differences):
    `normals`, `grad_s`, `grad_t (..., 3)`, the height's forward differences `hs`, `ht (...)`;
    unit normals, 0 where `normals` is 0."""
    n = jnp.asarray(normals)

    def tangential(g):
        g = jnp.asarray(g, n.dtype)
        along = dot(g, n)
        return [g[..., i] - along * n[..., i] for i in range(3)]

    # component by component, as `tilt`
    ts, tt = tangential(grad_s), tangential(grad_t)
    on = (n[..., 0] != 0) | (n[..., 1] != 0) | (n[..., 2] != 0)
    return unit_stack([jnp.where(on, n[..., i] - k_bump * (hs * ts[i] + ht * tt[i]), 0.0)
                       for i in range(3)])
