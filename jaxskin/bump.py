"""Bump-mapped normals in texture space (Bando 2001 §4.1, eq. 4.9–4.11).

    N'' = n + k_bump ∂h/∂s (n × (0, n_z, −n_y)) + k_bump ∂h/∂t ((n_z, 0, −n_x) × n)

with forward differences in texels (eq. 4.11; Δs = Δt = one texel, t pointing up, i.e. to
the previous row), then normalised. This is eq. 4.10, the form the paper obtains after
multiplying through by n_z: nothing divides by n_z, so it stays finite as n_z → 0.

n_z → 0 (the sides of a planar projection): there one texel spans a long stretch of
surface, so the pattern is stretched there and the bump is weak or odd. That is the paper's
known limitation (figs. 6.1(f), 6.2(f)); we keep eq. 4.10 exactly and do not hide it.
Both perturbation terms are perpendicular to n, so |N''| >= 1 wherever |n| = 1, and the
normalisation is safe; off the mesh (n = 0) a double `where` returns 0 with zero gradient.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = ["bump_normals", "height_gradient"]


def height_gradient(h: Float[ArrayLike, "H W"]) -> tuple[Array, Array]:
    """(∂h/∂s, ∂h/∂t) by forward differences in texels (eq. 4.11); 0 on the last column/row."""
    h = jnp.asarray(h)
    hs = jnp.pad(h[:, 1:] - h[:, :-1], ((0, 0), (0, 1)))
    ht = jnp.pad(h[:-1, :] - h[1:, :], ((1, 0), (0, 0)))  # t up: row r − 1 is t + Δt
    return hs, ht


def bump_normals(
    normals: Float[ArrayLike, "H W 3"], h: Float[ArrayLike, "H W"], k_bump
) -> Float[Array, "H W 3"]:
    """Perturbed unit normals `(H, W, 3)` from the interpolated normal map and height field.

    Differentiable in `normals`, `h` and `k_bump`.
    """
    n = jnp.asarray(normals)
    hs, ht = height_gradient(h)
    nx, ny, nz = n[..., 0], n[..., 1], n[..., 2]
    zero = jnp.zeros_like(nx)
    a = jnp.cross(n, jnp.stack([zero, nz, -ny], axis=-1))
    b = jnp.cross(jnp.stack([nz, zero, -nx], axis=-1), n)
    N = n + k_bump * (hs[..., None] * a + ht[..., None] * b)
    norm2 = jnp.sum(N * N, axis=-1, keepdims=True)
    ok = norm2 > 0
    return jnp.where(ok, N / jnp.sqrt(jnp.where(ok, norm2, 1.0)), 0.0)
