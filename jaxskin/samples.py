"""The view's samples that see the mesh, as a list: Blinn and Lafortune shade only those.

A view has `(k H) × (k W)` samples (`camera.supersample` k); the default hand fills about
a quarter of them. Shading every sample and zeroing the rest (as the renderer did) spends
three quarters of the work on the background; shading the list and averaging each pixel's
listed samples gives the same pixels (the same samples, shaded the same way, summed over
the same k × k block) for a quarter of the work (benchmarks/RESULTS.md, "What users
wait for").

The list is padded to a multiple of a sixteenth of the view's samples (the padding is
marked off, shaded as background and read by no pixel), so that a turn or a zoom, which
changes the count, changes the arrays' shapes, and so the compiled program, rarely.
Both directions of the pixel average are gathers (`_to_pixels`): XLA:CPU's scatter-add is
slow (see `view.transpose_table`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .linear import linear_call

__all__ = ["list_corners", "sample_list", "to_pixels"]

BUCKETS = 16  # the list's length is a multiple of 1/BUCKETS of the view's samples


def sample_list(tex, shaded, k: int, length: int | None = None) -> dict:
    """The list's arrays (numpy, in `Prepared.arrays`): per listed sample its flat index in
    the view `"list_index" (M,)`, its texture coordinates `"list_tex" (M, 2)`, whether it is
    one (not padding) `"list_on" (M,)` and its pixel `"list_pixel" (M,)`; per pixel its
    listed samples `"pixel_list" (H W, k²)`; for a view's samples `shaded (k H, k W)` (those that
    see a triangle's front) with texture coordinates `tex (k H, k W, 2)` and supersampling
    `k`. `length`: the list's length (at least the count); default: the count rounded up
    to a multiple of 1/`BUCKETS` of the samples."""
    shaded = np.asarray(shaded, bool)
    kH, kW = shaded.shape
    H, W = kH // k, kW // k
    idx = np.flatnonzero(shaded)
    M = idx.size
    if length is None:
        step = -(-shaded.size // BUCKETS)
        length = max(step, -(-M // step) * step)
    if length < M:
        raise ValueError(f"a list of {length} cannot hold {M} samples")
    row, col = idx // kW, idx % kW
    pixel = (row // k) * W + col // k
    list_index = np.zeros(length, np.int32)  # padding: sample 0 (read, never shown)
    list_index[:M] = idx
    list_tex = np.zeros((length, 2), np.float32)
    list_tex[:M] = np.asarray(tex, np.float32).reshape(-1, 2)[idx]
    list_on = np.zeros(length, bool)
    list_on[:M] = True
    list_pixel = np.full(length, H * W, np.int32)  # padding: the zero row past the pixels
    list_pixel[:M] = pixel
    pixel_list = np.full((H * W, k * k), length, np.int32)  # none: the zero row
    pixel_list[pixel, (row % k) * k + col % k] = np.arange(M, dtype=np.int32)
    return {"list_index": list_index, "list_tex": list_tex, "list_on": list_on,
            "list_pixel": list_pixel, "pixel_list": pixel_list}


def list_corners(list_tex, list_on, pad, shape: tuple[int, int], wrap_x: bool) -> np.ndarray:
    """The texels the listed samples' bilinear corners read, through the padding `pad`
    (`view.pad_index`) of a texture of `shape`: `(4, M)` int32 flat indices (0 on the
    padding), for `view.sample_corners`."""
    from .view import corners

    on = np.asarray(list_on, bool)
    where, texels, _ = corners(list_tex, on, pad, shape, wrap_x)
    out = np.zeros((4, on.size), np.int32)
    out[:, where] = texels
    return out


def to_pixels(values, list_pixel, pixel_list, pixels: tuple[int, int]):
    """The mean over each pixel's k × k samples of the listed samples' `values (M, C)`
    (samples not listed count as 0, as the background): `(H, W, C)`, linear in `values`;
    reverse mode gathers too. `pixels`: `(H, W)`."""
    return _to_pixels(tuple(pixels), values, (list_pixel, pixel_list))


def _mean(values, pixel_list):
    C = values.shape[-1]
    padded = jnp.concatenate([values, jnp.zeros((1, C), values.dtype)])
    read = padded[pixel_list]  # (H W, k², C); the k² summed as written (a short axis)
    return functools.reduce(lambda a, b: a + b, [read[:, j] for j in range(read.shape[1])]) \
        / pixel_list.shape[1]


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _to_pixels(pixels, values, table):
    return _rules(pixels)[0](*table, values)


@_to_pixels.defjvp
def _to_pixels_jvp(pixels, primals, tangents):
    values, table = primals
    out = _to_pixels(pixels, values, table)
    return out, linear_call(*_rules(pixels), tuple(table), (tangents[0],))


@functools.cache
def _rules(pixels):
    H, W = pixels

    def fun(list_pixel, pixel_list, values):
        return _mean(values, pixel_list).reshape(H, W, values.shape[-1])

    def transpose(list_pixel, pixel_list, ct):
        C = ct.shape[-1]
        padded = jnp.concatenate([ct.reshape(-1, C), jnp.zeros((1, C), ct.dtype)])
        return (padded[list_pixel] / pixel_list.shape[1],)

    return fun, transpose
