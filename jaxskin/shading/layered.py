"""Skin under cosmetics (Huang et al. 2013 §3): spectral Kubelka–Munk layers over measured
skin, subsurface scattering in texture space, and a Kelemen highlight per layer.

Per texel, with irradiance E = I_ambient + I_light max(0, N·L) (white light of the grid's
illuminant) and the cosmetic stack's `km.Slab` (R, T, R') over skin of reflectance R_s(λ):

    light entering the skin, times R_s:  E a(λ),  a = T R_s / (1 − R' R_s)
    light leaving through the cosmetics:  E T a(λ)        (without SSS)
    diffuse = E R(λ) + E T a(λ)  →  colour                  (= E · km.over(...), exact)

The geometric series 1/(1 − R' R_s) is the interreflection between the stack's underside
and the skin. With SSS the light leaving the skin, E a, is blurred by the six-Gaussian
profile (`jaxskin.sss`, an RGB profile, so the blur acts on the colour of E a) and then
passes the cosmetics again. That pass is spectral, T(λ), but after the blur only a colour
is left; it is applied as the factor t = XYZ(T a) / XYZ(a) per XYZ channel, which lies in
[0, 1] (T ≤ 1 and the colour-matching functions are ≥ 0), so it is stable for any
spectrum, where the same ratio in sRGB is not (saturated spectra give negative or zero
sRGB channels). Without blur the factor is exact. Huang et al. blur "the energy of light
passing through the cosmetics" the same way, in RGB.

Specular (§3.3): the skin's Kelemen highlight, then for each layer from the bottom up, the
highlight so far is dimmed by that layer's transmittance, in and out (the colour of
T_l(λ)²), and the layer's own highlight is added, weighted by its coverage
1 − exp(−X / `COVER_MM`): a layer that is not there has no surface. Huang et al. leave
this weight open; ours is 0 at X = 0 and saturates within a few microns.

Everything is written as a change from the bare skin (a − R_s, t − 1, T² − 1, coverage),
so zero thickness everywhere adds exact zeros: the image is bit for bit the one without
layers. Differentiable in every input (check_grads in tests/test_makeup.py).
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .. import km
from ..spectral import Grid
from . import kelemen

__all__ = ["COVER_MM", "irradiance", "radiance"]

COVER_MM = 0.001  # a layer's surface (its highlight) is there at a few microns


def irradiance(N, L, ambient, light):
    """E = I_ambient + I_light max(0, N·L) per texel: `(...)` from `N (..., 3)`."""
    return ambient + light * jnp.maximum(jnp.sum(N * L, axis=-1), 0.0)


def radiance(grid: Grid, N, L, V, ambient, light, skin_R, skin_roughness, skin_rho,
             S=None, K=None, X=None, roughness=None, rho=None, blur=None):
    """Linear sRGB leaving each texel: `(H, W, 3)`.

    **Arguments:**

    - `grid`: the spectral grid (static).
    - `N (H, W, 3)` unit normals; `L (3,)` unit direction to the light; `V (3,)` or
      `(H, W, 3)` unit directions to the viewer; `ambient`, `light`: I_ambient, I_light.
    - `skin_R (n,)`: the skin's reflectance on `grid`; `skin_roughness`, `skin_rho`: its
      Kelemen m and ρ_s.
    - `S, K (L, n)` per mm, `X (L, H, W)` mm, `roughness, rho (L,)`: the cosmetic layers,
      bottom (applied first) to top; `None` for bare skin (no KM work at all).
    - `blur`: a function from a colour image `(H, W, 3)` to the light leaving the skin
      (`jaxskin.sss.blur` with its texel size), or `None` for no subsurface scattering.
    """
    dtype = N.dtype
    to_rgb = jnp.asarray(grid.rgb_matrix, dtype)  # (n, 3)
    E = irradiance(N, L, ambient, light)[..., None]
    skin_rgb = skin_R @ to_rgb
    highlight = light * kelemen.specular(N, L, V, skin_roughness, skin_rho)[..., None]
    if X is None:
        skin = E * skin_rgb
        return (skin if blur is None else blur(skin)) + highlight

    R_l, T_l = km.layer(S[:, None, None, :], K[:, None, None, :], X[..., None])
    top = km.stack(R_l[::-1], T_l[::-1])  # km.stack wants the top layer first
    g = 1.0 / (1.0 - top.R_back * skin_R)
    da = skin_R * ((top.T - 1.0) + top.R_back * skin_R) * g  # a − R_s, exactly 0 bare
    a = skin_R + da
    dta = (top.T - 1.0) * a  # T a − a
    skin = E * (skin_rgb + da @ to_rgb)  # the colour of E a
    if blur is None:
        diffuse = E * (top.R @ to_rgb) + (skin + E * (dta @ to_rgb))
    else:
        to_xyz = jnp.asarray(grid.xyz_matrix, dtype)
        xyz_a, xyz_dta = a @ to_xyz, dta @ to_xyz
        ok = xyz_a > 1e-12
        t1 = jnp.where(ok, xyz_dta / jnp.where(ok, xyz_a, 1.0), -1.0)  # t − 1, in [−1, 0]
        xyz_to_rgb = jnp.asarray(grid.xyz_to_rgb, dtype)
        rgb_to_xyz = jnp.asarray(np.linalg.inv(grid.xyz_to_rgb), dtype)
        out = blur(skin)
        diffuse = E * (top.R @ to_rgb) + (out + (t1 * (out @ rgb_to_xyz)) @ xyz_to_rgb)

    for i in range(X.shape[0]):  # bottom to top
        dimming = (T_l[i] * T_l[i] - 1.0) @ to_rgb  # colour of T², minus white
        cover = -jnp.expm1(-X[i] / COVER_MM)[..., None]
        own = light * kelemen.specular(N, L, V, roughness[i], rho[i])[..., None]
        highlight = (highlight + highlight * dimming) + cover * own
    return diffuse + highlight

