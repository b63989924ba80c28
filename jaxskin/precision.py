"""Float32 products at full float32 accuracy on every device.

On NVIDIA GPUs since Ampere, XLA may compute float32 matrix products, einsums and
convolutions at its default precision in TF32 (a 10-bit mantissa: relative errors near
1e-3, where float32 gives 1e-7). The colour conversions (a spectrum's 41 bands summed
into XYZ), the texture-space interpolation and the fits' normal equations need float32's
accuracy, so every product in jaxskin goes through these helpers with
`jax.lax.Precision.HIGHEST`: exact float32 on a GPU, the same program on a CPU (where
float32 products are float32 anyway). tests/test_precision.py walks the traced renders
and fits and fails on any product left at the default.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

__all__ = ["HIGHEST", "einsum", "matmul"]

HIGHEST = jax.lax.Precision.HIGHEST


def matmul(a, b):
    """`a @ b` at float32 accuracy on every device (`precision=HIGHEST`)."""
    return jnp.matmul(a, b, precision=HIGHEST)


def einsum(subscripts: str, *operands):
    """`jnp.einsum` at float32 accuracy on every device (`precision=HIGHEST`)."""
    return jnp.einsum(subscripts, *operands, precision=HIGHEST)
