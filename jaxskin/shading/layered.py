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

import functools

import jax
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
    """Linear sRGB leaving each texel: `(..., 3)`.

    **Arguments:**

    - `grid`: the spectral grid (static).
    - `N (..., 3)` unit normals (any texel layout: an image, or a list of texels);
      `L (3,)` unit direction to the light; `V (3,)` or `(..., 3)` unit directions to the
      viewer; `ambient`, `light`: I_ambient, I_light (`light` may vary per texel, `(...)`:
      the light that reaches each one, as with shadows).
    - `skin_R (n,)`: the skin's reflectance on `grid` (or `(..., n)` per texel, a
      melanin map); `skin_roughness`, `skin_rho`: its
      Kelemen m and ρ_s.
    - `S, K (L, n)` per mm, `X (L, ...)` mm, `roughness, rho (L,)`: the cosmetic layers,
      bottom (applied first) to top; `None` for bare skin (no KM work at all).
    - `blur`: a function from the colour `(..., 3)` of the light entering the skin to the
      light leaving it (`jaxskin.sss.blur` with its texel size, on this layout), or `None`
      for no subsurface scattering.

    The spectral work is `_colours` (its docstring has how it is made fast on XLA:CPU,
    forward and derivative).
    """
    dtype = N.dtype
    to_rgb = jnp.asarray(grid.rgb_matrix, dtype)  # (n, 3)
    E = irradiance(N, L, ambient, light)[..., None]
    skin_rgb = skin_R @ to_rgb
    h = jnp.asarray(light)[..., None] * kelemen.specular(N, L, V, skin_roughness,
                                                        skin_rho)[..., None]  # white
    if X is None:
        skin = E * skin_rgb
        return (skin if blur is None else blur(skin)) + h

    # The highlights of the layers (white light), per layer and texel.
    h_l = jnp.stack([light * kelemen.specular(N, L, V, roughness[i], rho[i])
                     for i in range(X.shape[0])])
    shape = N.shape[:-1]
    flat = (X.reshape(X.shape[0], -1), E.reshape(-1, 1), h.reshape(-1, 1),
            h_l.reshape(X.shape[0], -1, 1), S, K, skin_R)
    colours = _colours(grid, blur is not None, *flat).reshape(*shape, -1)
    if blur is None:
        return (E * skin_rgb + h) + colours
    rgb_surface, xyz_da, xyz_dta = colours[..., :3], colours[..., 3:6], colours[..., 6:]
    to_xyz = jnp.asarray(grid.xyz_matrix, dtype)
    xyz_to_rgb = jnp.asarray(grid.xyz_to_rgb, dtype)
    skin = E * (skin_rgb + xyz_da @ xyz_to_rgb)  # the colour of E a
    xyz_a = skin_R @ to_xyz + xyz_da
    ok = xyz_a > 1e-12
    t1 = jnp.where(ok, xyz_dta / jnp.where(ok, xyz_a, 1.0), -1.0)  # t − 1, in [−1, 0]
    out = blur(skin)
    rgb_to_xyz = jnp.asarray(np.linalg.inv(grid.xyz_to_rgb), dtype)
    return (rgb_surface + (out + (t1 * (out @ rgb_to_xyz)) @ xyz_to_rgb)) + h


def _spectra(X, E, h, h_l, S, K, skin_R):
    """Per texel and band, for texels `(P,)`: the light reflected by the stack plus the
    highlights' change from the bare skin's (surface), a − R_s (da) and T a − a (dta),
    each `(P, n)` and exactly 0 for zero thickness. `X (L, P)`, `E, h (P, 1)`,
    `h_l (L, P, 1)`, `S, K (L, n)`, `skin_R (n,)`."""
    R_l, T_l = km.layer(S[:, None, :], K[:, None, :], X[..., None])
    top = km.stack(R_l[::-1], T_l[::-1])  # km.stack wants the top layer first
    g = 1.0 / (1.0 - top.R_back * skin_R)
    da = skin_R * ((top.T - 1.0) + top.R_back * skin_R) * g
    dta = (top.T - 1.0) * (skin_R + da)
    # The highlights bottom to top, as a spectrum: each is dimmed by T² of the layers
    # above. dD is the change from the skin's own highlight h.
    dD = jnp.zeros_like(top.R)
    for i in range(X.shape[0]):
        cover = -jnp.expm1(-X[i] / COVER_MM)[..., None]
        T2 = T_l[i] * T_l[i]
        dD = dD * T2 + h * (T2 - 1.0) + cover * h_l[i]
    return E * top.R + dD, da, dta


def _joint(grid, blurred, *args):
    """The colours `_colours` returns, computed in one program (for small chunks)."""
    surface, da, dta = _spectra(*args)
    to_rgb = jnp.asarray(grid.rgb_matrix, surface.dtype)
    if not blurred:
        return (surface + args[1] * (da + dta)) @ to_rgb
    to_xyz = jnp.asarray(grid.xyz_matrix, surface.dtype)
    return jnp.concatenate([surface @ to_rgb, da @ to_xyz, dta @ to_xyz], axis=-1)


CHUNK = 1024  # texels per step of the derivative's loop


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _colours(grid, blurred, X, E, h, h_l, S, K, skin_R):
    """The spectral work's colours per texel: without blur `(P, 3)`, the light reflected
    plus the light through the stack from the skin, as linear sRGB; with blur `(P, 9)`:
    rgb(surface), xyz(da), xyz(dta).

    Performance (XLA on CPU). Forward: without blur one spectral product; with it three,
    each computed apart (`_separately`). Derivatives: by the rule below, a loop over
    chunks of `CHUNK` texels, each chunk's tangent recomputed from its inputs
    (checkpointed), so that the many intermediates that XLA materialises for a derivative
    stay in the cache; reverse mode transposes that loop. Measured on the makeup face at
    1280×720 (benchmarks/bench_makeup.py): the gradient with respect to every thickness
    map takes 4.3–4.7× the forward pass, against 20–23× with plain autodiff.
    """
    if not blurred:
        return _joint(grid, False, X, E, h, h_l, S, K, skin_R)
    args = (X, E, h, h_l, S, K, skin_R)
    to_rgb = jnp.asarray(grid.rgb_matrix, X.dtype)
    to_xyz = jnp.asarray(grid.xyz_matrix, X.dtype)
    rgb_surface, xyz_da, xyz_dta = _separately(
        [lambda: _spectra(*args)[0] @ to_rgb, lambda: _spectra(*args)[1] @ to_xyz,
         lambda: _spectra(*args)[2] @ to_xyz])
    return jnp.concatenate([rgb_surface, xyz_da, xyz_dta], axis=-1)


@_colours.defjvp
def _colours_jvp(grid, blurred, primals, tangents):
    X = primals[0]
    P = X.shape[1]
    chunks = -(-P // CHUNK)
    pad = chunks * CHUNK - P
    # Tie every tangent to X's (adding 0 × one of its entries): inputs whose tangent is a
    # known zero otherwise make JAX's linearisation hoist their share of the work out of
    # the loop as full-size residuals (measured: 4× slower).
    tie = 0.0 * tangents[0][0, 0]
    tangents = [t + tie for t in tangents]

    def per_texel(a, axis):  # (..., P, ...) → (chunks, ..., CHUNK, ...)
        widths = [(0, 0)] * a.ndim
        widths[axis] = (0, pad)
        a = jnp.pad(a, widths)
        a = a.reshape(*a.shape[:axis], chunks, CHUNK, *a.shape[axis + 1:])
        return jnp.moveaxis(a, axis, 0)

    # X, E, h, h_l per texel; S, K per band; skin_R per band (n,) or per texel (P, n).
    texel_axes = (1, 0, 0, 1, None, None, 0 if primals[6].ndim == 2 else None)
    chunked = [i for i, ax in enumerate(texel_axes) if ax is not None]

    def merge(local, whole):  # the chunked arguments in their places among the whole ones
        out = list(whole)
        for i, a in zip(chunked, local, strict=True):
            out[i] = a
        return out

    @jax.checkpoint
    def one_chunk(local, local_dot):
        return jax.jvp(lambda *a: _joint(grid, blurred, *a), merge(local, primals),
                       merge(local_dot, tangents))[1]

    local = tuple(per_texel(primals[i], texel_axes[i]) for i in chunked)
    local_dot = tuple(per_texel(tangents[i], texel_axes[i]) for i in chunked)
    out_dot = jax.lax.map(lambda c: one_chunk(*c), (local, local_dot))
    out_dot = out_dot.reshape(-1, out_dot.shape[-1])[:P]
    return _colours(grid, blurred, *primals), out_dot


def _separately(fns):
    """`[f() for f in fns]` (arrays of one shape), each computed as its own XLA program:
    the branches of a `switch` inside a `map`. Computed together, XLA:CPU materialises the
    work the outputs share as many unfused arrays (measured: three spectral products
    took 7.5× one); apart, each fuses into one loop and the shared work is just redone
    (3 products: 2.7× one)."""
    return jax.lax.map(lambda k: jax.lax.switch(k, fns), jnp.arange(len(fns)))
