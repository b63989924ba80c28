"""The view's samples that see the mesh, as a list: Blinn and Lafortune shade only those.

A view has `(k H) × (k W)` samples (`camera.supersample` k); the default hand fills about
a quarter of them. Shading every sample and zeroing the rest (as the renderer did) spends
three quarters of the work on the background; shading the list and averaging each pixel's
listed samples gives the same pixels (the same samples, shaded the same way, summed over
the same k × k block) for a quarter of the work (benchmarks/RESULTS.md, "What users
wait for").

The list is padded to a multiple of `STEP` samples (the padding is marked off, shaded as
background and read by no pixel): little more than the count, since a view's turn, zoom or
field of view is part of the static configuration that `render` compiles for anyway. (The
editor, which compiles one program for every view of a scene, lists every sample.)
The pixels that show a listed sample (the covered pixels) are averaged, then placed in the
image, as two lists (`to_covered`, `place`): the renderer exposes and encodes them between.
Both steps are gathers in both directions (`_gather_mean`): XLA:CPU's scatter-add is slow
(see `view.transpose_table`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .linear import linear_call

__all__ = ["list_corners", "place", "sample_list", "to_covered", "to_pixels"]

STEP = 1024  # the list's length and the covered pixels' count are multiples of STEP


def sample_list(tex, shaded, k: int, length: int | None = None) -> dict:
    """The list's arrays (numpy, in `Prepared.arrays`), for a view's samples `shaded (k H,
    k W)` (those that see a triangle's front) with texture coordinates `tex (k H, k W, 2)`
    and supersampling `k`:

    - per listed sample: its flat index in the view `"list_index" (M,)`, its texture
      coordinates `"list_tex" (M, 2)`, whether it is one (not padding) `"list_on" (M,)`
      and its pixel's row among the covered pixels `"list_pixel" (M,)` (P: none);
    - per covered pixel (one with a listed sample): its listed samples `"pixel_list" (P,
      k²)` (M: none) and its flat index in the image `"covered_pixel" (P,)` (H W: none);
    - per pixel: its row among the covered pixels `"pixel_covered" (H W,)` (P: none).

    The covered pixels are averaged, exposed and encoded as a list too, then placed in the
    image (`to_covered`, `place`). `length`: the list's length (at least the count), and
    then every pixel is a row; default: the count rounded up to a multiple of `STEP`, and
    the covered pixels' count too."""
    shaded = np.asarray(shaded, bool)
    kH, kW = shaded.shape
    H, W = kH // k, kW // k
    idx = np.flatnonzero(shaded)
    M = idx.size
    given, length = length, _bucket(M) if length is None else length
    if length < M:
        raise ValueError(f"a list of {length} cannot hold {M} samples")
    row, col = idx // kW, idx % kW
    pixel = (row // k) * W + col // k
    covered, row_of = np.unique(pixel, return_inverse=True)
    # a list of a given length (the editor's, every sample): every pixel a row, so that
    # the shapes stay as they are when the view turns
    P = _bucket(covered.size) if given is None else H * W
    list_index = np.zeros(length, np.int32)  # padding: sample 0 (read, never shown)
    list_index[:M] = idx
    list_tex = np.zeros((length, 2), np.float32)
    list_tex[:M] = np.asarray(tex, np.float32).reshape(-1, 2)[idx]
    list_on = np.zeros(length, bool)
    list_on[:M] = True
    list_pixel = np.full(length, P, np.int32)  # padding: the zero row past the pixels
    list_pixel[:M] = row_of
    pixel_list = np.full((P, k * k), length, np.int32)  # none: the zero row
    pixel_list[row_of, (row % k) * k + col % k] = np.arange(M, dtype=np.int32)
    covered_pixel = np.full(P, H * W, np.int32)
    covered_pixel[:covered.size] = covered
    pixel_covered = np.full(H * W, P, np.int32)
    pixel_covered[covered] = np.arange(covered.size, dtype=np.int32)
    return {"list_index": list_index, "list_tex": list_tex, "list_on": list_on,
            "list_pixel": list_pixel, "pixel_list": pixel_list,
            "covered_pixel": covered_pixel, "pixel_covered": pixel_covered}


def _bucket(count: int) -> int:
    """`count` rounded up to a multiple of `STEP` (at least one step). A sixteenth of the
    view's samples before (a turn then rarely changed the shapes, which a CLI or library
    render recompiles for anyway): the like-for-like hand of `benchmarks/bench_mitsuba.py`
    shaded 81,920 rows for 68,665 samples, now 69,632."""
    return max(STEP, -(-count // STEP) * STEP)


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


def to_pixels(values, tables: dict, pixels: tuple[int, int]):
    """The mean over each pixel's k × k samples of the listed samples' `values (M, C)`
    (samples not listed count as 0, as the background): `(H, W, C)`, linear in `values`;
    reverse mode gathers too. `tables`: `sample_list`'s arrays; `pixels`: `(H, W)`."""
    return place(to_covered(values, tables), tables, pixels)


def to_covered(values, tables: dict):
    """The mean over each covered pixel's k × k samples of the listed samples' `values (M,
    C)`: `(P, C)`, in the order of `tables["covered_pixel"]` (0 on the padding)."""
    return _gather_mean(values, tables["pixel_list"], tables["list_pixel"])


def place(values, tables: dict, pixels: tuple[int, int]):
    """The covered pixels' `values (P, C)` in the image: `(H, W, C)`, 0 elsewhere."""
    H, W = pixels
    out = _gather_mean(values, tables["pixel_covered"][:, None], tables["covered_pixel"])
    return out.reshape(H, W, values.shape[-1])


def _gather_mean(values, rows, inverse):
    """`out[r] = mean_j values[rows[r, j]]` `(R, C)` (index N, past `values (N, C)`: 0),
    where each value is read by one row at most: row `inverse[n]` (R: none). Linear in
    `values`; reverse mode gathers through `inverse` (XLA:CPU's scatter-add is slow)."""
    return _gathered(values, (rows, inverse))


def _mean(rows, inverse, values):
    C = values.shape[-1]
    padded = jnp.concatenate([values, jnp.zeros((1, C), values.dtype)])
    read = padded[rows]  # (R, J, C); the J summed as written (a short axis)
    return functools.reduce(lambda a, b: a + b, [read[:, j] for j in range(read.shape[1])]) \
        / rows.shape[1]


def _mean_transpose(rows, inverse, ct):
    padded = jnp.concatenate([ct, jnp.zeros((1, ct.shape[-1]), ct.dtype)])
    return (padded[inverse] / rows.shape[1],)


@jax.custom_jvp
def _gathered(values, table):
    return _mean(*table, values)


@_gathered.defjvp
def _gathered_jvp(primals, tangents):
    values, table = primals
    return _gathered(values, table), linear_call(_mean, _mean_transpose, tuple(table),
                                                 (tangents[0],))
