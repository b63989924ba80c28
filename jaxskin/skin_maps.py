"""Skin maps from a texture: an sRGB albedo texture inverted, texel by texel, into the
biophysical skin's maps (`jaxskin.biophysical`) that reproduce its colour.

**What the texture means.** An albedo (or photo) texture holds, per texel, the sRGB colour
of the skin's diffuse reflectance under D65: the colour `spectral.to_rgb` gives the
biophysical reflectance (`biophysical.reflectance`, the specular k1 left out: the renderer
draws it as the highlight) on the scene's grid with `spectral.illuminant = "D65"`. So
the maps, rendered flat under D65 with no layers, give back the texture.

**What is fitted.** A colour has three numbers, so three values are fitted per texel, in
log space: the melanosome fraction (`melanin`: brown, darkness) and the blood fraction
(`haemoglobin`: red) within `biophysical.RANGES`, and a `brightness` (`BRIGHTNESS`), a
factor on the whole reflectance: a photo's shading and exposure, which the scattering
factor in its place could not follow (on the astronaut photo of `data/textures` it left
most of the face outside the model's colours). The others (eumelanin share, oxygenation,
epidermis thickness, scattering) are one value for the whole texture (`Fixed`, the
model's `DEFAULT` unless given).

**How.** The colour difference is CIELAB (white: a perfect reflector under the grid's
light). The inverse is tabulated once per call: the forward model on a coarse grid of
the three log-parameters, then, per cell of a regular CIELAB lattice, the nearest of those
as a start and damped Gauss–Newton steps (`solve`, vmapped) to the parameters whose colour
is nearest the cell's (only the cells the texture's colours fall in). Each distinct colour's
parameters are the lattice's, trilinearly interpolated at it, then corrected: looked up
again at the colour moved by the residual left (`invert`'s `polish`). Outside the skin's
gamut the parameters stop at their ranges: the nearest skin colour, and a large
residual.

**Skin or not.** A texel is skin where its fit's CIEDE2000 to the texture is at most
`SKIN_DE` (2.0: over twice the just-noticeable difference, where the fit inside the gamut
is near 0 and eyes, hair, lips, background and clothing lie well outside it), cleaned up
by a morphological opening and closing (3 × 3), so that single texels of noise do not
flip.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import numpy as np

from . import biophysical
from .spectral import Grid

__all__ = ["FREE", "SKIN_DE", "Fixed", "Inversion", "decode_srgb", "delta_e2000",
           "encode_srgb", "invert", "lab", "reflectance_of", "skin_mask", "solve", "table",
           "upsample"]

FREE = ("melanin", "haemoglobin", "brightness")  # fitted per texel
# The brightness's range: a photo's shading and exposure darken or lighten its skin by
# about this much (above 1: a bright photo; the reflectance may then exceed the model's).
BRIGHTNESS = (0.05, 2.0)
SKIN_DE = 2.0  # a texel's fit ΔE2000 up to which it is skin (module docstring)
_LATTICE = (41, 41, 41)  # the CIELAB lattice: L* 0–100, a* −30–70, b* −30–70
_LAB_LO = np.array([0.0, -30.0, -30.0])
_LAB_HI = np.array([100.0, 70.0, 70.0])
_COARSE = 16  # forward samples per log-parameter for the lattice's starts
_CHUNK = 1 << 16  # texels per vmapped block (bounds the memory: 65k × bands × 4 B)


class Fixed(NamedTuple):
    """The parameters held at one value over the texture (`biophysical.Skin` fields)."""

    eumelanin: float = float(biophysical.DEFAULT.eumelanin)
    oxygenation: float = float(biophysical.DEFAULT.oxygenation)
    epidermis_mm: float = float(biophysical.DEFAULT.epidermis_mm)
    scattering: float = float(biophysical.DEFAULT.scattering)


class Inversion(NamedTuple):
    """The maps of a texture `(H, W)` each: the fitted `melanin`, `haemoglobin`,
    `brightness` (values in `biophysical.RANGES`, `BRIGHTNESS`), the reproduced colour
    `rgb (H, W, 3)` (display sRGB, the texture's encoding), the CIEDE2000 `de` between texture and
    reproduction, and `skin` (bool: the texels the skin model explains)."""

    melanin: np.ndarray
    haemoglobin: np.ndarray
    brightness: np.ndarray
    rgb: np.ndarray
    de: np.ndarray
    skin: np.ndarray


def decode_srgb(v):
    """The sRGB transfer function's inverse (IEC 61966-2-1): display values → linear."""
    v = np.asarray(v, np.float64)
    return np.where(v <= 0.04045, v / 12.92, ((v + 0.055) / 1.055) ** 2.4)


def encode_srgb(x):
    """The sRGB transfer function (IEC 61966-2-1): linear light → display values."""
    x = np.clip(np.asarray(x, np.float64), 0.0, None)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def _matrices(grid: Grid):
    """Host float64: `W (n, 3)` reflectance → XYZ, `to_xyz (3, 3)` linear sRGB → XYZ and
    the white (a perfect reflector's XYZ)."""
    W = np.asarray(grid.xyz_matrix)
    return W, np.linalg.inv(np.asarray(grid.xyz_to_rgb)), W.sum(axis=0)


def lab(xyz, white):
    """CIELAB (CIE 15) of XYZ `(..., 3)` relative to `white (3,)`; jnp, differentiable
    (the cube root's linear part below (6/29)³)."""
    import jax.numpy as jnp

    t = xyz / jnp.asarray(white, xyz.dtype)
    d = 6.0 / 29.0
    big = t > d ** 3
    f = jnp.where(big, jnp.cbrt(jnp.where(big, t, 1.0)), t / (3 * d * d) + 4.0 / 29.0)
    return jnp.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]),
                      200.0 * (f[..., 1] - f[..., 2])], axis=-1)


def delta_e2000(lab1, lab2) -> np.ndarray:
    """CIEDE2000 between CIELAB arrays `(..., 3)` (colour-science's implementation)."""
    import colour

    return np.asarray(colour.delta_E(np.asarray(lab1, np.float64),
                                     np.asarray(lab2, np.float64), method="CIE 2000"))


def _bounds():
    ranges = {**biophysical.RANGES, "brightness": BRIGHTNESS}
    return np.log([ranges[k][0] for k in FREE]), np.log([ranges[k][1] for k in FREE])


def reflectance_of(c: biophysical.Chromophores, logp, fixed: Fixed):
    """The skin's diffuse reflectance `(..., n)` at log-parameters `logp (..., 3)` (the
    logs of `FREE`) with the rest at `fixed`: the brightness times the biophysical
    reflectance."""
    import jax.numpy as jnp

    p = jnp.exp(logp)
    skin = biophysical.Skin(melanin=p[..., 0], eumelanin=fixed.eumelanin,
                            haemoglobin=p[..., 1], oxygenation=fixed.oxygenation,
                            epidermis_mm=fixed.epidermis_mm, scattering=fixed.scattering)
    return p[..., 2:3] * biophysical.reflectance(c, skin)


def _forward(c, W, white, fixed):
    import jax.numpy as jnp

    def f(logp):
        return lab(reflectance_of(c, logp, fixed) @ jnp.asarray(W, logp.dtype), white)
    return f


def solve(c, grid: Grid, fixed: Fixed, target, start, steps: int = 8):
    """Damped Gauss–Newton in CIELAB from `start (N, 3)` log-parameters towards colours
    `target (N, 3)` (CIELAB), each step clipped to the ranges; vmapped (jit it, or call it
    inside a jitted function). Returns the log-parameters `(N, 3)` (jnp)."""
    import jax
    import jax.numpy as jnp

    W, _, white = _matrices(grid)
    f = _forward(c, W, white, fixed)
    lo, hi = (jnp.asarray(b, target.dtype) for b in _bounds())

    def one(t, p):
        def step(p, _):
            r = f(p) - t
            J = jax.jacfwd(f)(p)
            JtJ = J.T @ J
            lam = 1e-3 * jnp.trace(JtJ) / 3 + 1e-9  # Levenberg: tames a near-flat direction
            dp = jnp.linalg.solve(JtJ + lam * jnp.eye(3, dtype=p.dtype), -J.T @ r)
            return jnp.clip(p + dp, lo, hi), None
        return jax.lax.scan(step, p, None, length=steps)[0]

    return jax.vmap(one)(target, start)


def _fit(c, target, start, grid, fixed, steps):
    """`solve` (`steps` of it; 0: none) then the fitted colour, block by block: `(q, xyz)`,
    jitted once per grid, fixed values, steps and block shape."""
    return _fit_jit()(c, target, start, grid, fixed, steps)


@functools.cache
def _fit_jit():
    import jax  # here: importing this module does not import JAX
    import jax.numpy as jnp

    def fit(c, target, start, grid, fixed, steps):
        def block(ts):
            q = solve(c, grid, fixed, ts[0], ts[1], steps=steps) if steps else ts[1]
            R = reflectance_of(c, q, fixed)
            return q, R @ jnp.asarray(_matrices(grid)[0], R.dtype)
        return jax.lax.map(block, (target, start))
    return jax.jit(fit, static_argnums=(3, 4, 5))


def _blocks(a, size: int | None = None):
    """`a (N, 3)` padded (with its last row) to whole blocks `(B, size, 3)` float32; the
    size by default a power of 2 from 4096 to `_CHUNK` (few shapes: few compilations)."""
    import jax.numpy as jnp

    size = size or min(_CHUNK, max(4096, 1 << int(np.ceil(np.log2(max(len(a), 1))))))
    pad = -len(a) % size
    return jnp.asarray(np.pad(a, ((0, pad), (0, 0)), mode="edge").reshape(-1, size, 3),
                       jnp.float32)


def _lab_np(xyz, white):
    """`lab` on the host (NumPy, float64)."""
    t = np.asarray(xyz, np.float64) / white
    d = 6.0 / 29.0
    f = np.where(t > d ** 3, np.cbrt(t), t / (3 * d * d) + 4.0 / 29.0)
    return np.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]),
                     200.0 * (f[..., 1] - f[..., 2])], axis=-1)


def _lattice_index(lab_values):
    return (lab_values - _LAB_LO) / (_LAB_HI - _LAB_LO) * (np.array(_LATTICE) - 1)


def table(c, grid: Grid, fixed: Fixed, colours=None):
    """The inverse on the CIELAB lattice: log-parameters `(*_LATTICE, 3)` (host float64)
    whose colour is nearest each lattice point's; with `colours (N, 3)` (CIELAB), only at
    the corners of the cells they lie in (the rest are 0: never read for them)."""
    from scipy.spatial import cKDTree

    lo, hi = _bounds()
    axes = [np.linspace(a, b, _COARSE) for a, b in zip(lo, hi, strict=True)]
    coarse = np.stack(np.meshgrid(*axes, indexing="ij"), -1).reshape(-1, 3)
    coarse_lab = _lab_np(np.asarray(_fit(c, _blocks(coarse), _blocks(coarse), grid, fixed,
                                         0)[1]).reshape(-1, 3)[:len(coarse)], _matrices(grid)[2])
    shape = np.array(_LATTICE)
    if colours is None:
        needed = np.arange(int(np.prod(shape)))
    else:  # the 8 corners of each colour's cell
        base = np.clip(np.floor(_lattice_index(colours)).astype(np.int64), 0, shape - 2)
        corners = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
        cells = np.unique(np.ravel_multi_index(base.T, _LATTICE))  # 1-D: fast
        base = np.stack(np.unravel_index(cells, _LATTICE), -1)
        needed = np.unique(np.ravel_multi_index(
            (base[:, None, :] + corners).reshape(-1, 3).T, _LATTICE))
    points = np.stack(np.unravel_index(needed, _LATTICE), -1)
    lattice = _LAB_LO + points / (shape - 1) * (_LAB_HI - _LAB_LO)
    start = coarse[cKDTree(coarse_lab).query(lattice)[1]]
    q = np.asarray(_fit(c, _blocks(lattice), _blocks(start), grid, fixed,
                        10)[0], np.float64).reshape(-1, 3)[:len(lattice)]
    out = np.zeros((*_LATTICE, 3))
    out.reshape(-1, 3)[needed] = q
    return out


def _lookup(inverse, lab_values):
    """Trilinear interpolation of the lattice's log-parameters at CIELAB `(N, 3)`."""
    from scipy.ndimage import map_coordinates

    idx = np.clip(_lattice_index(lab_values), 0, np.array(_LATTICE) - 1)
    return np.stack([map_coordinates(inverse[..., k], idx.T, order=1, mode="nearest")
                     for k in range(3)], -1)


def invert(rgb, grid: Grid | None = None, fixed: Fixed | None = None, polish: int = 2,
           chromophores: biophysical.Chromophores | None = None) -> Inversion:
    """Invert a texture `rgb (H, W, 3)` (display sRGB in [0, 1]) into skin maps. Each
    distinct colour is fitted once (an 8-bit photo of 1024² has some 10⁵).

    **Arguments:**

    - `grid`: the spectral grid (its illuminant is the light the texture's colour is seen
      under); default 10 nm, D65 (the scene's default `spectral.step`).
    - `fixed`: the parameters held over the texture (default `Fixed()`).
    - `polish`: corrections per colour after the lattice's interpolation (0–8).
    - `chromophores`: the absorbers on `grid` (default: `biophysical.chromophores` with
      Prahl's haemoglobin table).

    **Returns:** an `Inversion`.
    """
    import jax.numpy as jnp

    from . import formats

    grid = grid or Grid(step=10)
    fixed = fixed or Fixed()
    rgb = np.asarray(rgb, np.float64)
    if rgb.ndim != 3 or rgb.shape[-1] != 3:
        raise ValueError(f"expected an (H, W, 3) texture, got shape {rgb.shape}")
    H, Wd = rgb.shape[:2]
    codes = np.round(rgb.reshape(-1, 3) * 65535).astype(np.int64)  # exact for 8/16-bit
    codes, inverse = np.unique((codes[:, 0] << 32) | (codes[:, 1] << 16) | codes[:, 2],
                               return_inverse=True)
    colours = np.stack([codes >> 32, (codes >> 16) & 65535, codes & 65535], -1) / 65535.0
    c_host = chromophores or biophysical.chromophores(grid.wavelengths,
                                                      formats.haemoglobin_table())
    c = biophysical.Chromophores(*(jnp.asarray(a, jnp.float32) for a in c_host))
    _, to_xyz, white = _matrices(grid)
    target = _lab_np(decode_srgb(colours) @ to_xyz, white)
    tab = table(c, grid, fixed, target)
    n = len(colours)

    def forward(p):
        xyz = np.asarray(_fit(c, _blocks(p), _blocks(p), grid, fixed, 0)[1], np.float64)
        return xyz.reshape(-1, 3)[:n]

    # The lattice as an approximate inverse, corrected: look up the target moved by the
    # residual so far (a fixed-point iteration; each step one forward evaluation, against
    # about four for a Gauss–Newton step's Jacobian), keeping each colour's best.
    aim, p = target, _lookup(tab, target)
    xyz = forward(p)
    err = np.linalg.norm(_lab_np(xyz, white) - target, axis=-1)
    last = xyz  # the colour the last aim gave: the next aim corrects that, not the best
    for _ in range(int(polish)):
        aim = aim + (target - _lab_np(last, white))
        p_new = _lookup(tab, aim)
        xyz_new = last = forward(p_new)
        err_new = np.linalg.norm(_lab_np(xyz_new, white) - target, axis=-1)
        better = err_new < err
        p[better], xyz[better], err[better] = p_new[better], xyz_new[better], err_new[better]
    de = delta_e2000(target, _lab_np(xyz, white))[inverse].reshape(H, Wd)
    rep = np.clip(encode_srgb(xyz @ np.linalg.inv(to_xyz)), 0, 1)[inverse].reshape(H, Wd, 3)
    maps = np.exp(p)[inverse].reshape(H, Wd, 3)
    return Inversion(maps[..., 0], maps[..., 1], maps[..., 2], rep, de, skin_mask(de))


def skin_mask(de, threshold: float = SKIN_DE) -> np.ndarray:
    """The texels the skin explains: fit ΔE2000 `de (H, W)` ≤ `threshold`, opened and
    closed by a 3 × 3 square (a lone texel of either kind follows its neighbours)."""
    from scipy import ndimage

    # padded with the edge's own values: scipy's operations treat the outside as 0, and a
    # closing would then drop the texture's border
    ok = np.pad(np.asarray(de) <= threshold, 2, mode="edge")
    box = np.ones((3, 3), bool)
    return ndimage.binary_closing(ndimage.binary_opening(ok, box), box)[2:-2, 2:-2]


def upsample(rgb, grid: Grid) -> np.ndarray:
    """Reflectance spectra `(..., n)` of display sRGB colours `rgb (..., 3)`: the smoothest
    spectrum (least squared second difference over the bands) whose linear sRGB under
    `grid`'s light is the colour's, clipped to [0, 1] (a very saturated colour then
    comes out a little duller). Linear in the linear colour, so one matrix; the
    colour of what the skin cannot explain (`Inversion.skin` 0: eyes, hair, clothing)
    under the same layers (Smits 1999 and Jakob & Hanika 2019 solve the same problem
    with smoother, bounded spectra at more cost)."""
    M = np.asarray(grid.rgb_matrix)  # (n, 3): linear sRGB = R @ M
    n = len(M)
    D = np.diff(np.eye(n), 2, axis=0)
    Q = np.linalg.inv(D.T @ D + 1e-6 * np.eye(n))
    A = Q @ M @ np.linalg.inv(M.T @ Q @ M)  # (n, 3): R = A @ c minimises |D R|², M'R = c
    return np.clip(decode_srgb(rgb) @ A.T, 0.0, 1.0)
