"""Dot products and lengths of 3-vectors on the last axis, written out component by component.

`jnp.sum(a * b, axis=-1)` over a last axis of three is a reduction along the minor
dimension, which XLA:CPU runs as an unvectorised loop per element: Blinn shading of the
default hand's 1024² samples took 44 ms that way and 2.2 ms written out as
a₀b₀ + a₁b₁ + a₂b₂ (benchmarks/RESULTS.md, "What users wait for"). The sum is the same
(the same three products, added in the same order); XLA may fuse the multiply-adds
differently, so results can differ in the last bit of float32.
"""

from __future__ import annotations

import jax.numpy as jnp

__all__ = ["dot", "times3", "unit", "unit_stack"]


def dot(a, b, keepdims: bool = False):
    """a · b over the last axis (length 3), broadcasting: `(...)`, or `(..., 1)` with
    `keepdims`."""
    a, b = jnp.asarray(a), jnp.asarray(b)
    d = a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]
    return d[..., None] if keepdims else d


def unit(v):
    """v / |v| over the last axis, 0 where v = 0 (a double `where`: value and gradient
    finite there)."""
    norm2 = dot(v, v, keepdims=True)
    ok = norm2 > 0
    return jnp.where(ok, v / jnp.sqrt(jnp.where(ok, norm2, 1.0)), 0.0)


def unit_stack(components):
    """`unit` of the vector whose three components are the arrays `components` (each
    `(...)`), stacked on a last axis: `(..., 3)`. Normalising the components before they
    are interleaved is a third faster on XLA:CPU (the 1024² bump normals 6.1 -> 4.9 ms)."""
    x, y, z = components
    norm2 = x * x + y * y + z * z
    ok = norm2 > 0
    length = jnp.sqrt(jnp.where(ok, norm2, 1.0))
    return jnp.stack([jnp.where(ok, c / length, 0.0) for c in (x, y, z)], axis=-1)


def times3(a, M):
    """`a @ M` for vectors `a (..., 3)` and a matrix `M (3, 3)`, written out as three
    broadcast products: as a `dot`, XLA:CPU runs the sum along the minor axis of three as
    an unvectorised loop per element (the colour after the SSS blur: 18.6 → 1.8 ms on the
    makeup face's 170,324 texels; the sum is the same, rounded alike but for fused
    multiply-adds)."""
    M = jnp.asarray(M, a.dtype)
    return a[..., 0:1] * M[0] + a[..., 1:2] * M[1] + a[..., 2:3] * M[2]
