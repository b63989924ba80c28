"""Subsurface scattering in texture space: the six-Gaussian skin profile (d'Eon & Luebke,
GPU Gems 3 ch. 14; constants in shared/reference/constants.md), as used by Huang et al. 2013.

    R(r) = Σᵢ wᵢ G(vᵢ, r),   G(v, r) = exp(−r²/2v) / (2πv),   r in mm

The weights of each RGB channel sum to 1, so on an unbounded surface the blur conserves
energy. On a mesh it is a normalised convolution: each texel's result is divided by the
blurred mask (the profile's mass that lands on the mesh around it), so a uniform field
stays uniform up to the mesh's edges, and a texel whose profile reaches off the mesh gives
its light only to the texels it reaches — energy is not conserved there: a unit impulse
at a straight edge at 0.1 mm texels keeps 0.81 of its red light at the edge, 0.94 two
texels in, 1.01 at 2.7 mm (tests/test_cosmetics.py measures it). `blur` convolves
with the whole profile sampled on the texel grid, by FFT (the default: exact, and on a CPU
faster than the alternative), or as the classic separable passes (each Gaussian's rows then
columns, cut at 3σ), masked either way. `blur_fft` is an independent NumPy float64
reference for the tests.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["VARIANCES_MM2", "WEIGHTS_RGB", "blur", "blur_fft", "kernel_radius", "mask_norm",
           "profile_kernels"]

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


def _kernel(variance_mm2: float, texel_mm: float, cut: float = 3.0) -> np.ndarray:
    r = kernel_radius(variance_mm2, texel_mm, cut)
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
                                            "SAME", precision=jax.lax.Precision.HIGHEST)

    x = conv(conv(x, (1, 2 * r + 1)), (2 * r + 1, 1))
    return jnp.moveaxis(x[:, 0], 0, -1)


def _profile_kernels(texel_mm: float) -> np.ndarray:
    """The sampled 2-D profile per RGB channel, `(3, 2r + 1, 2r + 1)`, each Gaussian
    normalised on the texel grid, to 4σ of the widest."""
    r = kernel_radius(VARIANCES_MM2[-1], texel_mm, cut=4.0)
    y, x = np.mgrid[-r:r + 1, -r:r + 1] * texel_mm
    rr = x * x + y * y
    # A narrow Gaussian (σ below a texel) point-sampled would carry several times its mass:
    # each is normalised on its own.
    gaussians = [np.exp(-rr / (2 * v)) for v in VARIANCES_MM2]
    gaussians = [g / g.sum() for g in gaussians]
    return np.stack([sum(w[c] * g for g, w in zip(gaussians, WEIGHTS_RGB, strict=True))
                     for c in range(3)])


def profile_kernels(texel_mm: float, shape: tuple[int, int]) -> np.ndarray:
    """The sampled 2-D profile per RGB channel that `blur` (FFT) convolves an image of
    `shape (H, W)` with, float64 `(3, 2 ry + 1, 2 rx + 1)`: each Gaussian sampled to 4σ of
    the widest and normalised there (on the texel grid), then cut to what the image can
    reach, `ry ≤ H − 1`, `rx ≤ W − 1` (beyond, the kernel meets only the zeros around the
    image: the same convolution). Built separably, each Gaussian as the outer product of
    its 1-D samples, so the whole 4σ window (9083² texels for 0.0036 mm texels) is never
    made. Inside jit, pass it as an argument (`blur(..., kernels=)`): as a closure it is a
    constant XLA folds into the program."""
    H, W = shape
    r = kernel_radius(VARIANCES_MM2[-1], texel_mm, cut=4.0)
    ry, rx = min(r, H - 1), min(r, W - 1)
    full = np.arange(-min(r, 4096), min(r, 4096) + 1) * texel_mm  # used where σ ≤ 50 texels
    y, x = np.arange(-ry, ry + 1) * texel_mm, np.arange(-rx, rx + 1) * texel_mm
    out = np.zeros((3, 2 * ry + 1, 2 * rx + 1))
    for v, w in zip(VARIANCES_MM2, WEIGHTS_RGB, strict=True):
        if math.sqrt(v) > 50 * texel_mm:  # Σ_|k|≤r exp(−(k t)²/2v) in closed form (Poisson
            # summation, ~1e-16 relative at σ > 50 t): the 4σ window is not made (it would
            # have 1e7 entries for 1e-6 mm texels)
            total = (math.sqrt(2 * math.pi * v) / texel_mm
                     * math.erf((r + 0.5) * texel_mm / math.sqrt(2 * v))) ** 2
        else:
            total = np.exp(-full * full / (2 * v)).sum() ** 2  # the whole window's mass
        g = np.outer(np.exp(-y * y / (2 * v)), np.exp(-x * x / (2 * v))) / total
        out += np.asarray(w)[:, None, None] * g
    return out


def _fft_convolve(images, kernels):
    """Same-size linear convolution of `images (B, H, W)` with `kernels (B, ky, kx)` (odd
    sizes, centred)."""
    B, H, W = images.shape
    ky, kx = kernels.shape[-2:]
    shape = (H + ky - 1, W + kx - 1)
    f = jnp.fft.rfft2(images, shape) * jnp.fft.rfft2(kernels, shape)
    ry, rx = (ky - 1) // 2, (kx - 1) // 2
    return jnp.fft.irfft2(f, shape)[:, ry:ry + H, rx:rx + W]


def blur(irradiance, texel_mm: float, mask=None, method: str = "fft", cut: float = 3.0,
         norm=None, kernels=None):
    """The skin profile applied to `irradiance (H, W, 3)` (linear RGB) in texture space.

    **Arguments:**

    - `irradiance`: light entering the skin per texel.
    - `texel_mm`: the size of one texel on the surface, in mm (static: it sets the kernels).
    - `mask`: `(H, W)` texels on the mesh (default: all). Texels off it neither give nor
      take light; the result is renormalised by the blurred mask, so edges do not darken.
    - `method`: `"fft"` (default): the whole sampled 2-D profile by FFT convolution, exact;
      `"separable"`: each Gaussian as row and column passes cut at `cut` σ. On a CPU the
      FFT is exact and several times faster than the separable passes at any cut worth
      using (benchmarks/bench_sss.py).

    - `norm`: `mask_norm(mask, texel_mm)`, computed once for a fixed mask (FFT only;
      default: computed here). A renderer passes it to save three FFTs a frame.
    - `kernels`: `profile_kernels(texel_mm, (H, W))` (FFT only; default: made here). Inside
      jit pass it as an argument, as the renderer does: made here it is a constant of the
      program (up to 3 × (2H − 1) × (2W − 1) floats), which XLA pads and folds at compile
      time.

    **Returns:** the light leaving the skin per texel, `(H, W, 3)`. Differentiable in
    `irradiance`.
    """
    E = jnp.asarray(irradiance)
    if E.ndim != 3 or E.shape[-1] != 3:
        raise ValueError(f"sss.blur: irradiance must be (H, W, 3) linear RGB, got shape "
                         f"{E.shape}")
    m = jnp.ones(E.shape[:2], E.dtype) if mask is None else jnp.asarray(mask, E.dtype)
    if m.shape != E.shape[:2]:
        raise ValueError(f"sss.blur: mask {m.shape} must be the image's (H, W) = "
                         f"{E.shape[:2]}")
    Em = E * m[..., None]
    if method == "fft":
        if kernels is None:
            kernels = profile_kernels(texel_mm, E.shape[:2])
        kernels = jnp.asarray(kernels, E.dtype)
        num = _fft_convolve(jnp.moveaxis(Em, -1, 0), kernels)
        den = mask_norm(m, texel_mm, kernels) if norm is None else jnp.asarray(norm, E.dtype)
        # Texels the mask reaches, relative to the kernel's mass within the image: with
        # texels far below the profile's mm (a mesh 1e6 times too small) that mass is
        # ~1e-8, and an absolute 1e-6 would make the image black
        ok = den > 1e-6 * jnp.sum(kernels, axis=(1, 2))[:, None, None]
        out = jnp.moveaxis(jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0), 0, -1)
        return out * m[..., None]
    if method != "separable":
        raise ValueError(f"method must be 'fft' or 'separable', got {method!r}")
    out = jnp.zeros_like(E)
    for v, w in zip(VARIANCES_MM2, WEIGHTS_RGB, strict=True):
        kernel = _kernel(v, texel_mm, cut)
        num = _separable(Em, kernel)
        den = _separable(m[..., None], kernel)
        r = (len(kernel) - 1) // 2  # the kernel's mass within the image's reach
        reach = (kernel[max(r - E.shape[0] + 1, 0):r + E.shape[0]].sum()
                 * kernel[max(r - E.shape[1] + 1, 0):r + E.shape[1]].sum())
        ok = den > 1e-6 * reach
        out = out + jnp.asarray(w, E.dtype) * jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)
    return out * m[..., None]


def mask_norm(mask, texel_mm: float, kernels=None):
    """The mask blurred by each channel's profile, `(3, H, W)`: what `blur` (FFT) divides
    by so that the mesh's edges do not darken. `kernels`: as `blur`'s."""
    m = jnp.asarray(mask)
    m = m.astype(m.dtype if jnp.issubdtype(m.dtype, jnp.floating) else jnp.float32)
    if kernels is None:
        kernels = profile_kernels(texel_mm, m.shape)
    kernels = jnp.asarray(kernels, m.dtype)
    return _fft_convolve(jnp.broadcast_to(m, (3, *m.shape)), kernels)


def blur_fft(irradiance, texel_mm: float):
    """Reference, in NumPy float64: the sampled 2-D profile (`_profile_kernels`) convolved
    by FFT over a zero-padded image; no mask."""
    E = np.asarray(irradiance, np.float64)
    H, W, _ = E.shape
    kernels = _profile_kernels(texel_mm)
    k = kernels.shape[-1]
    r = (k - 1) // 2
    shape = (H + k - 1, W + k - 1)
    out = np.zeros_like(E)
    for c in range(3):
        full = np.fft.irfft2(np.fft.rfft2(E[..., c], shape) * np.fft.rfft2(kernels[c], shape),
                             shape)
        out[..., c] = full[r:r + H, r:r + W]
    return out
