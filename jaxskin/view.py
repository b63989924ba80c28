"""Camera views: rasterize the mesh from a camera, then sample the texture-space result.

Visibility (which triangle a pixel sees) comes from the same rasterizer as texture space
and is fixed per configuration; what follows — interpolating texture coordinates and
sampling the texture-space colour image bilinearly — is differentiable in the image
(nvdiffrast's split). Orthographic by default, like the paper (the mesh's bounding box
fills the image); perspective with perspective-correct barycentrics. `supersample` renders
k × k samples per pixel and averages them (antialiasing); `coverage` is the fraction of a
pixel's samples that see the mesh (the alpha of an RGBA image).

Bilinear samples near a silhouette read texels just outside the mesh's part of texture
space; `pad_index` fills those with their nearest texel on the mesh (computed once, a
gather in the traced function), so no dark rim of background texels bleeds in.

The camera looks down −z; `rotate` (degrees about x, then y, then z) turns the mesh, as
the paper's mouse does, and the normals with it (§5.3).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .linear import linear_call
from .projection import TextureMap
from .raster import Raster, rasterize

__all__ = ["PIXEL_TABLE", "View", "bilinear", "blend", "blend_corners", "corners", "coverage",
           "downsample",
           "hidden_side_share", "make_view", "pad_index", "pixel_entries", "pixel_table",
           "rotation", "sample", "sample_corners", "sample_padded", "transpose_table",
           "view_pixels"]

MARGIN = 0.05
PAD = 3  # texels of padding around the mesh's texels (bilinear reads reach one)


def rotation(degrees) -> np.ndarray:
    """The 3×3 rotation about x, then y, then z (degrees)."""
    ax, ay, az = np.radians(np.asarray(degrees, np.float64))
    rx = np.array([[1, 0, 0], [0, math.cos(ax), -math.sin(ax)], [0, math.sin(ax), math.cos(ax)]])
    ry = np.array([[math.cos(ay), 0, math.sin(ay)], [0, 1, 0], [-math.sin(ay), 0, math.cos(ay)]])
    rz = np.array([[math.cos(az), -math.sin(az), 0], [math.sin(az), math.cos(az), 0], [0, 0, 1]])
    return rz @ ry @ rx


@dataclasses.dataclass(frozen=True, eq=False)
class View:
    """Per image pixel (at the supersampled size): the texture coordinate it sees
    `tex (H, W, 2)` in texels, `mask (H, W)`; the model rotation `R`, the `eye` (None for
    orthographic), whether texture x wraps (a cylinder), and the `raster` (triangle and
    barycentrics, perspective-corrected) each sample sees, and where each vertex lands
    (`xy`, pixels of the supersampled image)."""

    tex: np.ndarray
    mask: np.ndarray
    R: np.ndarray
    eye: np.ndarray | None
    wrap_x: bool
    raster: Raster | None = None
    xy: np.ndarray | None = None  # (V, 2) the mesh's vertices in (supersampled) pixels
    # Perspective: the image plane's shift in half-widths and half-heights (x right, y up),
    # which centres the projected mesh: the optical axis meets the (unzoomed) image at pixel
    # (W/2 (1 + shift_x), H/2 (1 − shift_y)).
    shift: tuple = (0.0, 0.0)
    # Samples that see the front of a triangle (its outward side faces the camera); the
    # others look into an open mesh (through the wrist, the face's back) and are drawn
    # black: the texture holds the outside's shading only. None: every sample in `mask`.
    front: np.ndarray | None = None

    @property
    def shaded(self) -> np.ndarray:
        """`mask` less the samples that see a triangle's back: where colour is sampled."""
        return self.mask if self.front is None else self.mask & self.front


def make_view(tmap: TextureMap, size: int, projection: str = "orthographic",
              supersample: int = 1, fov: float = 30.0, rotate=(0.0, 0.0, 0.0),
              height: int = 0, zoom: float = 1.0, center=(0.0, 0.0)) -> View:
    """The view of `tmap`'s mesh in an image `size` pixels wide and `height` high (0:
    square); the mesh fills the image's shorter side, less a margin (orthographic: its
    bounding box; perspective: its projection, every vertex inside, the pinhole on the axis
    through the bounding box's centre).

    `zoom` magnifies that frame about `center` (fractions of the frame from its middle, x
    right, y up): a crop of the image plane, so the view at `zoom` 2 is exactly the middle
    of the view at twice the size, for either projection (the pinhole stays put)."""
    mesh = tmap.mesh
    n = size * supersample
    m = (height or size) * supersample
    R = rotation(rotate)
    v = mesh.vertices @ R.T
    lo, hi = v.min(axis=0), v.max(axis=0)
    centre = (lo + hi) / 2
    if projection == "orthographic":
        extent = hi[:2] - lo[:2]
        scale = (1 - 2 * MARGIN) * min(n / max(extent[0], 1e-300), m / max(extent[1], 1e-300))
        xy = np.stack([(v[:, 0] - centre[0]) * scale + n / 2,
                       m / 2 - (v[:, 1] - centre[1]) * scale], axis=1)
        depth, eye, w, shift = -v[:, 2], None, None, (0.0, 0.0)
    elif projection == "perspective":
        # A pinhole on the axis through the bounding box's centre, as near as lets every
        # vertex project inside the frame less the margin, and the frame centred on the
        # projected mesh (a shift of the image plane; the pinhole stays on the axis). `fov`
        # spans the image's width, pixels are square. A flat mesh facing the camera fills
        # the frame as its bounding box does in the orthographic view.
        focal = 1.0 / math.tan(math.radians(fov) / 2)
        d, shift = _pinhole(v - centre, focal, n / m)
        eye = centre + np.array([0.0, 0.0, d])
        c = v - eye  # camera space, looking down -z
        w = -c[:, 2]
        xy = np.stack([n / 2 * (1 + focal * c[:, 0] / w + shift[0]),
                       m / 2 * (1 - (focal * c[:, 1] / w * n / m + shift[1]))], axis=1)
        depth = w
    else:
        raise ValueError(f"camera projection must be orthographic or perspective, got "
                         f"{projection!r}")
    if zoom != 1.0 or any(center):
        focus = np.array([n * (0.5 + center[0]), m * (0.5 - center[1])])
        xy = (xy - focus) * zoom + np.array([n / 2, m / 2])
    r = rasterize(xy, mesh.faces, m, n, depth=depth)
    bary = r.bary.astype(np.float64)
    safe = np.where(r.tri >= 0, r.tri, 0)
    if w is not None:  # perspective-correct: weights b_i / w_i, renormalised
        bary = bary / w[mesh.faces[safe]]
        bary /= np.maximum(bary.sum(axis=-1, keepdims=True), 1e-300)
    corners = tmap.face_corners()  # (F, 3, 2) texture coordinates, unwrapped at the seam
    tex = np.einsum("hwk,hwkc->hwc", bary, corners[safe])
    # The outward side faces the camera where the triangle's normal (right-hand rule, the
    # mesh turned outward on loading) points to the eye: +z (orthographic), or toward the
    # pinhole from the triangle.
    a, b, c = (v[mesh.faces[:, i]] for i in range(3))
    normal = np.cross(b - a, c - a)
    toward = normal[:, 2] if eye is None else np.einsum("fk,fk->f", normal,
                                                        eye - (a + b + c) / 3)
    front = r.mask & (toward[safe] >= 0)
    return View(tex.astype(np.float32), r.mask, R, eye, tmap.wrap_x,
                Raster(r.tri, bary.astype(np.float32)), xy, tuple(float(a) for a in shift),
                front)


def hidden_side_share(tmap: TextureMap, view: View) -> float:
    """The share of the samples `view` shades whose texel belongs to a triangle facing the
    other way along z than the sample's own (a planar map gives the texels both sides of a
    part project to to one side, `TextureMap.side`): those show the other side's shading,
    lit as if they faced the other way. 0 for the other projections."""
    if tmap.kind != "planar" or view.raster is None:
        return 0.0
    shaded = view.shaded
    seen = int(shaded.sum())
    if seen == 0:
        return 0.0
    mesh = tmap.mesh
    a, b, c = (mesh.vertices[mesh.faces[:, i]] for i in range(3))
    facing = np.cross(b - a, c - a)[:, 2] >= 0  # per face: toward +z
    own = view.raster.tri[shaded]
    x = np.clip(view.tex[shaded][:, 0].astype(int), 0, tmap.width - 1)
    y = np.clip(view.tex[shaded][:, 1].astype(int), 0, tmap.height - 1)
    owner = tmap.raster.tri[y, x]
    other = (owner >= 0) & (facing[np.maximum(owner, 0)] != facing[own])
    return float(other.sum() / seen)


def _pinhole(c, focal: float, aspect: float):
    """The perspective camera's distance `d` from the bounding box's centre and the image
    plane's shift `(2,)` (in half-widths and half-heights) for vertices `c (V, 3)` relative
    to that centre: the nearest pinhole on the +z axis at which every vertex projects
    inside the frame less `MARGIN` on each side once the projection is centred. The
    projected extent shrinks as the pinhole backs away, so `d` is found by bisection (to
    1e-9 of the mesh's size); with the pinhole too near, vertices spill out of the frame
    (a face at fov 60 lost its forehead and chin)."""
    size = max(float(np.ptp(c, axis=0).max()), 1e-300)
    near = float(c[:, 2].max()) + 1e-6 * size  # every vertex in front of the pinhole
    limit = 2 * (1 - 2 * MARGIN)

    def projected(d):
        w = d - c[:, 2]
        return focal * c[:, 0] / w, focal * c[:, 1] / w * aspect

    def fits(d):
        x, y = projected(d)
        return max(np.ptp(x), np.ptp(y)) <= limit

    lo, hi = near, near + size * (focal + 1)
    while not fits(hi):
        lo, hi = hi, 2 * hi - near
    if fits(lo):
        hi = lo
    for _ in range(200):
        if hi - lo <= 1e-9 * size:
            break
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if fits(mid) else (mid, hi)
    x, y = projected(hi)
    return hi, np.array([-(x.max() + x.min()) / 2, -(y.max() + y.min()) / 2])


def sample(image, tex, mask, wrap_x: bool, background=0.0):
    """Bilinear samples of a texture-space `image (Ht, Wt, C)` at the texture coordinates
    `tex (H, W, 2)` of a view (`View.tex`, `View.mask`): `(H, W, C)`, `background` where the
    view sees no mesh. Differentiable in `image`."""
    image = jnp.asarray(image)
    Ht, Wt = image.shape[:2]
    x0, y0, fx, fy = bilinear(tex)

    def at(xi, yi):
        xi = jnp.mod(xi, Wt) if wrap_x else jnp.clip(xi, 0, Wt - 1)
        return image[jnp.clip(yi, 0, Ht - 1).astype(jnp.int32), xi.astype(jnp.int32)]

    out = blend(at(x0, y0), at(x0 + 1, y0), at(x0, y0 + 1), at(x0 + 1, y0 + 1), fx, fy)
    return jnp.where(jnp.asarray(mask)[..., None], out, background)


def bilinear(tex):
    """Where bilinear samples at texture coordinates `tex (..., 2)` (texel centres at
    half-integers) read: the lower corner `x0, y0 (...)` and the fractions `fx, fy (..., 1)`."""
    x = jnp.asarray(tex)[..., 0] - 0.5
    y = jnp.asarray(tex)[..., 1] - 0.5
    x0, y0 = jnp.floor(x), jnp.floor(y)
    return x0, y0, (x - x0)[..., None], (y - y0)[..., None]


def blend(c00, c10, c01, c11, fx, fy):
    """The bilinear sample of the corners' values `(..., C)` (00, 10, 01, 11) at the
    fractions `fx, fy (..., 1)` (`bilinear`)."""
    return ((1 - fx) * (1 - fy) * c00 + fx * (1 - fy) * c10
            + (1 - fx) * fy * c01 + fx * fy * c11)


def pad_index(mask, wrap_x: bool, width: int = PAD) -> np.ndarray:
    """Flat texel indices `(H, W)` that pad a texture-space image beyond `mask (H, W)`:
    each texel off the mesh within `width` texels (8-connected steps) of it takes its
    nearest texel on the mesh (the first found, in a fixed order of neighbours); every
    other texel itself. `image.reshape(-1, C)[index]` is the padded image. Texture x wraps
    across a cylinder's seam when `wrap_x`."""
    mask = np.asarray(mask, bool)
    H, W = mask.shape
    index = np.arange(H * W).reshape(H, W)
    filled = mask.copy()
    steps = [(dy, dx) for dy in (-1, 0, 1) for dx in (-1, 0, 1) if dy or dx]
    steps.sort(key=lambda s: abs(s[0]) + abs(s[1]))  # edge neighbours before corners
    for _ in range(width):
        new_index, new_filled = index.copy(), filled.copy()
        for dy, dx in steps:
            src_filled = _shift(filled, dy, dx, wrap_x, False)
            src_index = _shift(index, dy, dx, wrap_x, 0)
            take = ~new_filled & src_filled
            new_index[take], new_filled[take] = src_index[take], True
        index, filled = new_index, new_filled
    return index


def _shift(a, dy, dx, wrap_x, fill):
    """`a` moved so that out[i, j] = a[i + dy, j + dx]: `fill` beyond the edges, except
    along x when it wraps."""
    out = np.roll(a, (-dy, -dx), axis=(0, 1))
    if dy:
        out[(-1 if dy > 0 else 0), :] = fill
    if dx and not wrap_x:
        out[:, (-1 if dx > 0 else 0)] = fill
    return out


def coverage(mask, k: int):
    """The fraction of each pixel's k × k samples that see the mesh: `(H, W)` float32 from
    a view's `mask (k H, k W)` (alpha, antialiased as the colour is)."""
    return downsample(jnp.asarray(mask, jnp.float32)[..., None], k)[..., 0]


def downsample(image, k: int):
    """The mean of each k × k block: supersamples `(k H, k W, C)` → pixels `(H, W, C)`."""
    if k == 1:
        return image
    H, W, C = image.shape
    return image.reshape(H // k, k, W // k, k, C).mean(axis=(1, 3))


def transpose_table(tex, mask, pad, shape, wrap_x: bool, width: int = 16) -> dict:
    """The transpose of `sample_padded` (a gather of the bilinear samples) as a table, so
    that reverse mode reads instead of scattering: XLA's scatter-add of every sample's four
    corners into the texture is slow (half a second at 1280×720, supersample 2). Each row
    lists up to `width` (4 × sample + corner, weight) pairs that land on one texel (`"view_rows"`,
    `"view_weights"`, `(R, width)`; empty slots weigh 0) and the texel (`"view_dest"`,
    `(R,)`, sorted); a texel read by more samples gets more rows. The weights are stored in
    float32; a float64 gradient recomputes them from the coordinates (exact). Made once per
    view (numpy), from the view's texture coordinates `tex (H, W, 2)`, its `mask (H, W)`,
    the padding `pad (Ht, Wt)` (`pad_index`) and the texture's `shape (Ht, Wt)`."""
    where, texels, weights = corners(tex, mask, pad, shape, wrap_x)
    samples = (4 * where + np.arange(4)[:, None]).reshape(-1)  # corner-major, as the others
    texels, weights = texels.reshape(-1), weights.reshape(-1)
    rows, w, dest = _grouped(texels, samples, weights, width)
    return {"view_rows": rows, "view_weights": w, "view_dest": dest}


def corners(tex, mask, pad, shape, wrap_x: bool):
    """The bilinear reads of every sample that sees the mesh, as `sample` makes them: the
    samples' flat indices `where (N,)`, and per corner (00, 10, 01, 11) the padded texel it
    reads `(4, N)` and its weight `(4, N)` float64."""
    Ht, Wt = shape
    tex = np.asarray(tex, np.float64)
    where = np.flatnonzero(np.asarray(mask, bool))
    x = tex[..., 0].reshape(-1)[where] - 0.5
    y = tex[..., 1].reshape(-1)[where] - 0.5
    x0, y0 = np.floor(x), np.floor(y)
    fx, fy = x - x0, y - y0
    texels, weights = [], []
    for dx, dy, w in [(0, 0, (1 - fx) * (1 - fy)), (1, 0, fx * (1 - fy)), (0, 1, (1 - fx) * fy),
                      (1, 1, fx * fy)]:
        xi = np.mod(x0 + dx, Wt) if wrap_x else np.clip(x0 + dx, 0, Wt - 1)
        yi = np.clip(y0 + dy, 0, Ht - 1)
        texels.append(np.asarray(pad).reshape(-1)[yi.astype(np.int64) * Wt + xi.astype(np.int64)])
        weights.append(w)
    return where, np.stack(texels), np.stack(weights)


def pixel_entries(tex, mask, pad, shape, wrap_x: bool, k: int):
    """The view's pixels as a sparse map of the texture image (the padded texture's
    bilinear samples averaged over each pixel's k × k supersamples): `(pixel, texel,
    weight)` flat indices and float64 weights, the entries of one pixel on one texel summed,
    sorted by pixel, then texel."""
    Ht, Wt = shape
    W = np.asarray(mask).shape[1]
    where, texels, weights = corners(tex, mask, pad, shape, wrap_x)
    pixel = (where // W // k) * (W // k) + (where % W) // k
    key = np.tile(pixel, 4).astype(np.int64) * (Ht * Wt) + texels.reshape(-1)
    key, inverse = np.unique(key, return_inverse=True)
    merged = np.bincount(inverse.reshape(-1), weights.reshape(-1) / (k * k))
    return key // (Ht * Wt), key % (Ht * Wt), merged


def _grouped(dest, src, weights, width: int):
    """Entries `(dest, src, weight)` as a table for gathers: rows of up to `width` (src,
    weight) pairs of one dest, `(R, width)` int32 and float32 (empty slots weigh 0), and
    each row's dest `(R,)`, sorted; a dest with more entries gets more rows."""
    order = np.argsort(dest, kind="stable")
    dest, src, weights = dest[order], src[order], weights[order]
    width = max(1, min(width, int(np.bincount(dest).max()) if dest.size else 1))
    starts = np.flatnonzero(np.r_[True, dest[1:] != dest[:-1]]) if dest.size else \
        np.zeros(0, np.int64)
    counts = np.diff(np.r_[starts, dest.size])
    rows_per = -(-counts // width)
    first_row = np.r_[0, np.cumsum(rows_per)[:-1]]
    group = np.repeat(np.arange(starts.size), counts)
    pos = np.arange(dest.size) - starts[group]
    row = first_row[group] + pos // width
    R = int(rows_per.sum())
    rows = np.zeros((R, width), np.int32)
    w = np.zeros((R, width), np.float32)
    rows[row, pos % width] = src
    w[row, pos % width] = weights
    return rows, w, np.repeat(dest[starts], rows_per).astype(np.int32)


def pixel_table(tex, mask, pad, shape, wrap_x: bool, k: int) -> dict:
    """The view's colour per pixel as one linear map of the texture image: the padded
    texture's bilinear samples (`sample_padded`) averaged over each pixel's k × k
    supersamples (`downsample`), with the entries of one pixel that land on one texel
    merged (at 1280×720, supersample 2: 4.5 M sample corners, 1.6 M entries). Two tables
    (`_grouped`): by pixel for the forward pass (`"pix_src"` texels, `"pix_w"`,
    `"pix_dest"` flat pixels; rows of 8) and by texel for its transpose (`"pix_t_src"`
    pixels, `"pix_t_w"`, `"pix_t_dest"` texels; rows of 16): both passes read, neither
    scatters. Weights in float32 (the forward and its transpose use the same ones). Made
    once per view (numpy) from `pixel_entries`."""
    pix, tx, merged = pixel_entries(tex, mask, pad, shape, wrap_x, k)
    src, w, dest = _grouped(pix, tx, merged, 8)
    t_src, t_w, t_dest = _grouped(tx, pix, merged, 16)
    return {"pix_src": src, "pix_w": w, "pix_dest": dest,
            "pix_t_src": t_src, "pix_t_w": t_w, "pix_t_dest": t_dest}


PIXEL_TABLE = ("pix_src", "pix_w", "pix_dest", "pix_t_src", "pix_t_w", "pix_t_dest")


def view_pixels(image, table, pixels: tuple[int, int]):
    """`downsample(sample_padded(image, ...), k)` through `pixel_table`'s arrays (in
    `PIXEL_TABLE`'s order): the view's pixels `(H, W, C)` of a texture image `(Ht, Wt, C)`,
    linear in it; reverse mode reads the transposed table. `pixels`: `(H, W)`."""
    return _view_pixels(tuple(pixels), image, tuple(table))


def _apply(src, w, dest, values, n: int):
    """Rows of `(src, weight)` gathered from `values (N, C)` and summed into `dest`: `(n, C)`.
    Each entry's C values gathered together, and a row's sum written out entry by entry: as
    `jnp.sum` along the row (a minor axis of 8 or 16) XLA:CPU runs an unvectorised loop per
    element (the makeup frame's pixels at 1280×720: 47 → 7 ms CPU, one gather per channel
    and the sum 22 ms)."""
    w = w.astype(values.dtype)
    g = values[src]  # (rows, k, C)
    read = g[:, 0] * w[:, 0:1]
    for j in range(1, src.shape[1]):
        read = read + g[:, j] * w[:, j:j + 1]
    return jnp.zeros((n, values.shape[1]), values.dtype).at[dest].add(read,
                                                                       indices_are_sorted=True)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _view_pixels(pixels, image, table):
    return _pixel_rules(pixels, image.shape)[0](*table, image)


@_view_pixels.defjvp
def _view_pixels_jvp(pixels, primals, tangents):
    image, table = primals
    out = _view_pixels(pixels, image, table)
    return out, linear_call(*_pixel_rules(pixels, image.shape), tuple(table), (tangents[0],))


@functools.cache
def _pixel_rules(pixels, shape):
    def fun(src, w, dest, t_src, t_w, t_dest, image):
        C = image.shape[-1]
        return _apply(src, w, dest, image.reshape(-1, C), pixels[0] * pixels[1]).reshape(
            *pixels, C)

    def transpose(src, w, dest, t_src, t_w, t_dest, ct):
        C = ct.shape[-1]
        return (_apply(t_src, t_w, t_dest, ct.reshape(-1, C), shape[0] * shape[1])
                .reshape(shape),)

    return fun, transpose


def sample_padded(image, pad, tex, mask, wrap_x: bool, table=None):
    """`sample` of `image (Ht, Wt, C)` padded by `pad` (`pad_index`): the view's colour.
    With `table` (`transpose_table`'s three arrays, in its order) reverse mode reads the
    table instead of scattering (forward mode and values are the same either way). Only
    `image` is differentiated (the view's coordinates are fixed)."""
    if table is None:
        return _padded_sample(wrap_x, image, pad, tex, mask)
    return _sample_with_table(wrap_x, image, (pad, tex, mask, *table))


def sample_corners(image, corners, tex, mask, table=None):
    """`sample_padded` at samples whose corners' texels are known: `corners (4, N)` flat
    indices into `image (Ht, Wt, C)`, through the padding (`corners`, made once per view),
    for samples at `tex (N, 2)`, `mask (N,)`: `(N, C)`, the same values (the same texels
    and weights, added in the same order) without padding the whole image first. `table`:
    `transpose_table`'s, for reverse mode, as there."""
    if table is None:
        return _corner_sample(image, corners, tex, mask)
    return _corners_with_table(image, (corners, tex, mask, *table))


def blend_corners(values, tex, mask):
    """The bilinear samples at `tex (N, 2)` of the values `(4, N, C)` at their corners (00,
    10, 01, 11, as `corners` orders them): `(N, C)`, 0 where not `mask (N,)`."""
    _, _, fx, fy = bilinear(tex)
    out = blend(*(values[i] for i in range(4)), fx, fy)
    return jnp.where(jnp.asarray(mask)[..., None], out, 0.0)


def _corner_sample(image, corners, tex, mask, *table):
    flat = image.reshape(-1, image.shape[-1])
    return blend_corners([flat[corners[i]] for i in range(4)], tex, mask)


@jax.custom_jvp
def _corners_with_table(image, residuals):
    return _corner_sample(image, *residuals)


@_corners_with_table.defjvp
def _corners_with_table_jvp(primals, tangents):
    image, residuals = primals
    out = _corners_with_table(image, residuals)
    return out, linear_call(*_corner_rules(image.shape), tuple(residuals), (tangents[0],))


@functools.cache
def _corner_rules(shape):
    def fun(corners, tex, mask, rows, weights, dest, image):
        return _corner_sample(image, corners, tex, mask)

    def transpose(corners, tex, mask, rows, weights, dest, ct):  # as `sample_padded`'s
        return _sample_rules(False, shape)[1](None, tex, mask, rows, weights, dest, ct)

    return fun, transpose


def _padded_sample(wrap_x, image, pad, tex, mask, *table):
    C = image.shape[-1]
    padded = image.reshape(-1, C)[pad]
    return sample(padded, tex, mask, wrap_x)


@functools.partial(jax.custom_jvp, nondiff_argnums=(0,))
def _sample_with_table(wrap_x, image, residuals):
    return _padded_sample(wrap_x, image, *residuals)


@_sample_with_table.defjvp
def _sample_with_table_jvp(wrap_x, primals, tangents):
    image, residuals = primals
    out = _sample_with_table(wrap_x, image, residuals)
    return out, linear_call(*_sample_rules(wrap_x, image.shape), tuple(residuals),
                            (tangents[0],))


@functools.cache
def _sample_rules(wrap_x, shape):
    def fun(pad, tex, mask, rows, weights, dest, image):
        return _padded_sample(wrap_x, image, pad, tex, mask)

    def transpose(pad, tex, mask, rows, weights, dest, ct):
        C = ct.shape[-1]
        sample = rows // 4
        if ct.dtype == jnp.float32:
            w = weights
        else:  # float64: the weights from the coordinates, as `sample` computes them
            corner = rows % 4
            xy = tex.reshape(-1, 2).astype(ct.dtype)[sample] - 0.5
            f = xy - jnp.floor(xy)
            wx = jnp.where(corner % 2 == 1, f[..., 0], 1 - f[..., 0])
            wy = jnp.where(corner // 2 == 1, f[..., 1], 1 - f[..., 1])
            w = jnp.where(weights != 0, wx * wy, 0.0)
        # One gather per channel: 2.5× faster than gathering (R, width, C) rows.
        read = jnp.stack([jnp.sum(ct[..., c].reshape(-1)[sample] * w, axis=1) for c in range(C)],
                         axis=-1)
        out = jnp.zeros((shape[0] * shape[1], C), ct.dtype).at[dest].add(
            read, indices_are_sorted=True)
        return (out.reshape(shape),)

    return fun, transpose
