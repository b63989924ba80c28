"""The loss: per-pixel weights, the target's noise estimate and the maps' total-variation
prior."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from jaxskin import render

PRIOR_EPS = 0.01  # the total variation's smoothing, in map units: sqrt(d² + ε²) − ε


def weights(config, params, target_alpha=None, mask=None):
    """Per-pixel weights `(H, W)`: 1 where the mesh covers the pixel fully (its coverage,
    `render`'s alpha, is 1), times the target's alpha and the mask (each in [0, 1])."""
    alpha = np.asarray(render.render(config, params, "rgba"))[..., 3]
    w = (alpha >= 1.0 - 1e-6).astype(np.float64)
    for extra in (target_alpha, mask):
        if extra is not None:
            w = w * np.clip(np.asarray(extra, np.float64), 0.0, 1.0)
    return w


def noise_sigma(image, w, min_pixels: int = 100) -> float | None:
    """The noise σ of `image (H, W, C)` (display values) estimated from its pixel-to-pixel
    variation where `w (H, W) > 0`, or `None` where fewer than `min_pixels` pixels have all
    eight neighbours there.

    Immerkær 1996, "Fast noise variance estimation": the image filtered with the 3×3 kernel
    [[1, −2, 1], [−2, 4, −2], [1, −2, 1]], which is 0 on any plane (a smooth shading
    gradient leaves no response) and turns white noise of σ into a response of standard
    deviation 6σ (the kernel's squares sum to 36); so σ = sqrt(π/2) mean|response| / 6.
    Texture, edges and wrinkles add to the response: for a render the value is an upper
    estimate of the noise, which keeps `run_command`'s warning from crying wolf."""
    img = np.asarray(image, np.float64)
    if img.ndim == 2:
        img = img[..., None]
    inside = np.asarray(w) > 0
    H, W = inside.shape
    if H < 3 or W < 3:
        return None
    k = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])
    response = np.zeros((H - 2, W - 2, img.shape[-1]))
    full = np.ones((H - 2, W - 2), bool)
    for dy in range(3):
        for dx in range(3):
            response += k[dy, dx] * img[dy:dy + H - 2, dx:dx + W - 2]
            full &= inside[dy:dy + H - 2, dx:dx + W - 2]
    if full.sum() < min_pixels:
        return None
    return float(np.sqrt(np.pi / 2.0) * np.abs(response[full]).mean() / 6.0)


# fit-image warns when its RMS ends above this many times the target's noise (and above
# half an 8-bit step, the least difference a PNG can hold).
ABOVE_NOISE = 3.0


def texel_pairs(mask: np.ndarray):
    """Neighbouring texel pairs (right and down) with both texels on the mesh: two index
    arrays into the flattened texture."""
    H, W = mask.shape
    idx = np.arange(H * W).reshape(H, W)
    a = [idx[:, :-1][mask[:, :-1] & mask[:, 1:]], idx[:-1][mask[:-1] & mask[1:]]]
    b = [idx[:, 1:][mask[:, :-1] & mask[:, 1:]], idx[1:][mask[:-1] & mask[1:]]]
    return np.concatenate(a), np.concatenate(b)


def total_variation(m, pairs, eps: float = PRIOR_EPS):
    """The smoothed total variation of a map `m (H, W)` over `pairs`: the mean over pairs
    of sqrt(d² + ε²) − ε (d: the pair's difference); 0 for a constant map, ≈ mean |d| for
    steps much larger than ε, smooth everywhere."""
    flat = m.reshape(-1)
    d = flat[pairs[0]] - flat[pairs[1]]
    return jnp.mean(jnp.sqrt(d * d + eps * eps) - eps)
