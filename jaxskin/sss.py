"""Subsurface scattering in texture space: the six-Gaussian skin profile (d'Eon & Luebke,
GPU Gems 3 ch. 14; constants in shared/reference/constants.md), as used by Huang et al. 2013.

    R(r) = Σᵢ wᵢ G(vᵢ, r),   G(v, r) = exp(−r²/2v) / (2πv),   r in mm

The weights of each RGB channel sum to 1, so the blur conserves energy. Each Gaussian is
separable: blurring the rows and then the columns of an image with a 1-D kernel of
variance vᵢ (in texels², from the texel size in mm) is exactly its 2-D blur, cut at 3σ.
`blur` does that, masked (texels off the mesh neither give nor take light; the result is
renormalised by the blurred mask, so the mesh's edge does not darken). `blur_fft` is the
reference: the whole 2-D profile by FFT convolution, cut only at 4σ of the widest Gaussian,
no mask.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["VARIANCES_MM2", "WEIGHTS_RGB", "blur", "blur_fft", "kernel_radius"]

VARIANCES_MM2 = (0.0064, 0.0484, 0.187, 0.567, 1.99, 7.41)
WEIGHTS_RGB = (
    (0.233, 0.455, 0.649),
    (0.100, 0.336, 0.344),
    (0.118, 0.198, 0.000),
    (0.113, 0.007, 0.007),
    (0.358, 0.004, 0.000),
    (0.078, 0.000, 0.000),
)


def kernel_radius(variance_mm2: float, texel_mm: float, cut: float = 3.0) -> int:
    """Half-width in texels of a Gaussian's 1-D kernel, cut at `cut` σ."""
    return int(math.ceil(cut * math.sqrt(variance_mm2) / texel_mm))


def _kernel(variance_mm2: float, texel_mm: float) -> np.ndarray:
    r = kernel_radius(variance_mm2, texel_mm)
    x = np.arange(-r, r + 1) * texel_mm
    k = np.exp(-x * x / (2 * variance_mm2))
    return k / k.sum()  # the cut tails' mass goes back to the kernel


def _separable(image, kernel):
    """Rows then columns with a 1-D kernel, zero outside; image (H, W, C)."""
    H, W, C = image.shape
    r = (len(kernel) - 1) // 2
    k = jnp.asarray(kernel, image.dtype)
    x = jnp.moveaxis(image, -1, 0)[:, None]  # (C, 1, H, W): channels as the batch

    def conv(x, kernel_shape):
        return jax.lax.conv_general_dilated(x, k.reshape(kernel_shape)[None, None], (1, 1),
                                            "SAME")

    x = conv(conv(x, (1, 2 * r + 1)), (2 * r + 1, 1))
    return jnp.moveaxis(x[:, 0], 0, -1)


def blur(irradiance, texel_mm: float, mask=None):
    """The skin profile applied to `irradiance (H, W, 3)` (linear RGB) in texture space.

    **Arguments:**

    - `irradiance`: light entering the skin per texel.
    - `texel_mm`: the size of one texel on the surface, in mm (static: it sets the kernels).
    - `mask`: `(H, W)` texels on the mesh (default: all).

    **Returns:** the light leaving the skin per texel, `(H, W, 3)`. Differentiable in
    `irradiance`.
    """
    E = jnp.asarray(irradiance)
    m = jnp.ones(E.shape[:2], E.dtype) if mask is None else jnp.asarray(mask, E.dtype)
    out = jnp.zeros_like(E)
    Em = E * m[..., None]
    for v, w in zip(VARIANCES_MM2, WEIGHTS_RGB, strict=True):
        kernel = _kernel(v, texel_mm)
        num = _separable(Em, kernel)
        den = _separable(m[..., None], kernel)
        ok = den > 1e-6
        out = out + jnp.asarray(w, E.dtype) * jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)
    return out * m[..., None]


def blur_fft(irradiance, texel_mm: float):
    """Reference: the 2-D profile R(r) sampled per texel (each Gaussian normalised), to 4σ
    of the widest, convolved by FFT over a zero-padded image; no mask."""
    E = np.asarray(irradiance, np.float64)
    H, W, _ = E.shape
    r_max = kernel_radius(VARIANCES_MM2[-1], texel_mm, cut=4.0)
    y, x = np.mgrid[-r_max:r_max + 1, -r_max:r_max + 1] * texel_mm
    rr = x * x + y * y
    out = np.zeros_like(E)
    shape = (H + 2 * r_max + 1, W + 2 * r_max + 1)
    # Each Gaussian sampled on the texel grid and normalised on its own: a narrow one
    # (σ below a texel) point-sampled would otherwise carry several times its mass.
    gaussians = [np.exp(-rr / (2 * v)) for v in VARIANCES_MM2]
    gaussians = [g / g.sum() for g in gaussians]
    for c in range(3):
        profile = sum(w[c] * g for g, w in zip(gaussians, WEIGHTS_RGB, strict=True))
        full = np.fft.irfft2(np.fft.rfft2(E[..., c], shape) * np.fft.rfft2(profile, shape),
                             shape)
        out[..., c] = full[r_max:r_max + H, r_max:r_max + W]
    return out
