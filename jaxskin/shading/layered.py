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
sRGB channels). Without blur the factor is exact. With blur, the light reaching a texel
comes partly from its neighbours (bare skin beside a lipstick's edge), and unequal X, Y, Z
factors can take that light out of the gamut: at a strongly absorbing layer's edge, t ≈ 0
for X and Z but not Y leaves red below 0 and green above. There
the result is moved toward the blurred light dimmed by t_Y alone, just far enough that no
channel is below 0, or below the texel's own light where a saturated stack makes that
negative (`_in_gamut`); nowhere else is it changed. Huang et al. blur "the
energy of light passing through the cosmetics" the same way, in RGB.

Specular (§3.3): the skin's Kelemen highlight, then for each layer from the bottom up, the
highlight so far is dimmed by that layer's transmittance, in and out (the colour of
T_l(λ)²), and the layer's own highlight is added, weighted by its coverage
1 − exp(−X / `COVER_MM`): a layer that is not there has no surface. Huang et al. leave
this weight open; ours is 0 at X = 0 and saturates within a few microns.

Everything is written as a change from the bare skin (a − R_s, t − 1, T² − 1, coverage),
so zero thickness everywhere adds exact zeros: the image is bit for bit the one without
layers. Differentiable in every input (check_grads in tests/test_makeup.py and
tests/test_fast_gradients.py; reverse mode by hand-written transposes, see `_colours`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .. import km
from ..linear import linear_call
from ..precision import matmul
from ..spectral import Grid
from ..vectors import dot, times3
from . import kelemen

__all__ = ["COVER_MM", "irradiance", "radiance"]

COVER_MM = 0.001  # a layer's surface (its highlight) is there at a few microns


def irradiance(N, L, ambient, light):
    """E = I_ambient + I_light max(0, N·L) per texel: `(...)` from `N (..., 3)`."""
    return ambient + light * jnp.maximum(dot(N, L), 0.0)


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
    skin_rgb = matmul(skin_R, to_rgb)
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
    skin = E * (skin_rgb + times3(xyz_da, xyz_to_rgb))  # the colour of E a
    xyz_a = matmul(skin_R, to_xyz) + xyz_da
    ok = xyz_a > 1e-12
    t1 = jnp.where(ok, xyz_dta / jnp.where(ok, xyz_a, 1.0), -1.0)  # t − 1, in [−1, 0]
    out = blur(skin)
    rgb_to_xyz = jnp.asarray(np.linalg.inv(grid.xyz_to_rgb), dtype)
    x = out + times3(t1 * times3(out, rgb_to_xyz), xyz_to_rgb)
    own = skin + E * times3(xyz_dta, xyz_to_rgb)  # E rgb(T a): the texel's own, unblurred
    return (rgb_surface + _in_gamut(x, (1.0 + t1[..., 1:2]) * out,
                                    jnp.minimum(own, 0.0))) + h


def _in_gamut(x, y, floor):
    """`x`, the light leaving through the layers after the blur, moved toward `y` (the blurred
    light dimmed by the luminance factor alone: ≥ 0 where the light that arrived is) just
    far enough that no channel is below `floor` (0, or the texel's own light where that is
    negative: a saturated spectrum's colour, which the factor gives exactly where the light
    is uniform): x + λ (y − x) with the least λ in [0, 1]. Where no channel is below its
    floor — wherever the light is uniform, and every pixel of the built-in scenes — x
    itself (a floor of 0 alone would move the uniform light of saturated stacks too, and a
    per-texel Gauss–Newton fit of the maps stalls on that)."""
    bad = (x < floor) & (y > floor)
    lam = jnp.where(bad, (floor - x) / jnp.where(bad, y - x, 1.0), 0.0)  # y − x > 0 there
    # the largest of the three written out (a reduction along the minor axis of three:
    # see `vectors.times3`)
    most = jnp.maximum(jnp.maximum(lam[..., 0:1], lam[..., 1:2]), lam[..., 2:3])
    return x + most * (y - x)


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


def _spectra_skipping(X, E, h, h_l, S, K, skin_R):
    """`_spectra` for one chunk of texels, each layer in the form the chunk needs
    (`lax.switch` on the chunk's thicknesses): absent from every texel (X = 0: R = 0, T = 1,
    no highlight, so the layer changes nothing and is skipped: composing it would give the
    same values, bit for bit), uniform over the chunk (its R and T computed once per band,
    as the foundation over the whole face) or varying (per texel and band). The stack is
    built from the bottom up, as `km.stack` does. (A `fori_loop` over the layers, one
    program for all four, compiles in less time but ran 40 % slower.)"""
    c, n = X.shape[1], S.shape[1]
    zeros, ones = jnp.zeros((c, n), X.dtype), jnp.ones((c, n), X.dtype)

    def add(i, uniform, x, hl, state):  # layer i on the stack so far (None: the skin)
        if uniform:
            R_i, T_i = (jnp.broadcast_to(a, (c, n)) for a in km.layer(S[i], K[i], x[0]))
        else:
            R_i, T_i = km.layer(S[i], K[i], x)
        acc, dD = state
        slab = (R_i, T_i, R_i) if acc is None else tuple(km.compose((R_i, T_i), acc))
        cover = -jnp.expm1(-x / COVER_MM)
        T2 = T_i * T_i
        return slab, dD * T2 + h * (T2 - 1.0) + cover * hl

    state = (None, zeros)
    for i in range(X.shape[0]):
        x = X[i][:, None]
        if state[0] is None:  # the bottom layer so far: absent leaves the bare skin's slab
            def absent(x, hl, state):
                return (zeros, ones, zeros), state[1]
        else:
            def absent(x, hl, state):
                return state
        branches = [absent] + [functools.partial(add, i, uniform) for uniform in (True, False)]
        which = jnp.where(jnp.all(x == 0), 0, jnp.where(jnp.all(x == x[0]), 1, 2))
        state = jax.lax.switch(which, branches, x, h_l[i], state)
    (R, T, Rb), dD = state
    g = 1.0 / (1.0 - Rb * skin_R)
    da = skin_R * ((T - 1.0) + Rb * skin_R) * g
    dta = (T - 1.0) * (skin_R + da)
    return E * R + dD, da, dta


def _forward_chunked(grid, blurred, X, E, h, h_l, S, K, skin_R):
    """`_colours`' value on a CPU: `_joint` with `_spectra_skipping`, in a loop over chunks
    of `FORWARD_CHUNK` texels (the last one padded). In cache-sized chunks the work the
    three colours share is computed once and kept (over the whole face XLA:CPU would
    materialise it as full-size arrays, and three programs apart, each fused into one loop,
    redo it); and the chunk lets a layer be skipped where it is absent and computed once per
    band where it is uniform (on the makeup face: the foundation everywhere, the other
    three layers on 2-12 % of the texels each). One chunk a step: two side by side (as the
    transpose's `STREAMS`) measured no faster and doubled the compile time."""
    P, per = X.shape[1], skin_R.ndim == 2

    def per_texel(a, axis):
        return _per_texel(a, axis, P, FORWARD_CHUNK)

    local = (per_texel(X, 1), per_texel(E, 0), per_texel(h, 0), per_texel(h_l, 1),
             per_texel(skin_R, 0) if per else None)

    def one(c):
        x, e, hh, hl, sk = c
        return _joint(grid, blurred, x, e, hh, hl, S, K, sk if per else skin_R,
                      spectra=_spectra_skipping)

    out = jax.lax.map(one, local)
    return out.reshape(-1, out.shape[-1])[:P]


def _joint(grid, blurred, *args, spectra=None):
    """The colours `_colours` returns, computed in one program (for small chunks), by
    `spectra` (default `_spectra`)."""
    surface, da, dta = (spectra or _spectra)(*args)
    to_rgb = jnp.asarray(grid.rgb_matrix, surface.dtype)
    if not blurred:
        return matmul(surface + args[1] * (da + dta), to_rgb)
    to_xyz = jnp.asarray(grid.xyz_matrix, surface.dtype)
    return jnp.concatenate([matmul(surface, to_rgb), matmul(da, to_xyz), matmul(dta, to_xyz)],
                           axis=-1)


# Texels per step of the derivative's loops. Not 1024: with 41 bands a (1024, 41) float32
# array is 41 × 4 KiB, so every intermediate of a chunk starts at the same offset in a
# page, and the transpose alone is slower at 1024 than at 500–3000 on a CPU (likely
# cache-set aliasing among the ~30 arrays a fusion reads; benchmarks/RESULTS.md). Inside
# the whole render's gradient the difference is within the noise.
CHUNK = 1000
# Chunks per step of the transpose's loop, computed side by side (`_cotangents_chunked`).
STREAMS = 2
# Texels per chunk of the forward pass on a CPU (`_forward_chunked`): 4096 × 41 bands of
# float32 is 672 KiB an intermediate, about a core's L2; 1024-8192 measured within 10 %
# of each other, 512 and 16384 slower (benchmarks/RESULTS.md).
FORWARD_CHUNK = 4096
# On a GPU the loops' steps are launches: one chunk of up to WIDE_CHUNK texels a step
# (262,144 × 41 float32 bands: 43 MB an intermediate), so the makeup face's 170,324
# texels at the default 512² texture are one step, not 86 steps of two chunks.
WIDE_CHUNK = 262_144


def _chunking(P: int, wide: int | None = None) -> tuple[int, int]:
    """`(texels a chunk, chunks a step)` of the transpose's loop over `P` texels: on a CPU
    `(CHUNK, STREAMS)` (cache-sized chunks, two threads' worth a step); elsewhere one chunk
    a step, as few chunks of at most `wide` texels (default `WIDE_CHUNK`) as cover `P`,
    of equal size (so the last is not mostly padding)."""
    if _cpu_form("chunks"):
        return CHUNK, STREAMS
    chunks = max(1, -(-P // (wide or WIDE_CHUNK)))
    return max(1, -(-P // chunks)), 1


def _cpu_form(name: str) -> bool:
    """Whether to trace the form written for XLA:CPU of `name`, rather than the plain one a
    GPU compiler fuses well: whether JAX's default backend is the CPU when the function is
    traced (a computation placed on the CPU of a GPU machine, `jax.default_device`, gets
    the GPU's forms: the same values, not the CPU's speed):

    - `"chunks"`: the derivative's loops over cache-sized chunks (`_chunking`,
      `_chunked_tangent`);
    - `"forward"`: the colours' value in a loop over chunks of texels that skips absent
      layers (`_forward_chunked`), not as one program over every texel;
    - `"skip"`: a layer absent from a whole chunk skips its S and K sums (`lax.cond`);
    - `"sums"`: sums over bands and texels as products with ones (`_rowsum`, `_colsum`).

    The figures for both kinds of device: benchmarks/RESULTS.md."""
    return jax.default_backend() == "cpu"


@functools.partial(jax.custom_jvp, nondiff_argnums=(0, 1))
def _colours(grid, blurred, X, E, h, h_l, S, K, skin_R):
    """The spectral work's colours per texel: without blur `(P, 3)`, the light reflected
    plus the light through the stack from the skin, as linear sRGB; with blur `(P, 9)`:
    rgb(surface), xyz(da), xyz(dta).

    Performance (XLA on CPU). Forward: `_forward_chunked`, a loop over chunks of texels,
    each chunk's three spectral products in one program, a layer absent from the chunk
    skipped and one uniform over it computed per band. Forward mode: `_chunked_tangent`, a loop over
    chunks of texels, each chunk's tangent by `jax.jvp` of `_joint`,
    checkpointed. Reverse mode: that tangent's transpose written by hand (`_cotangents`,
    through `linear.linear_call`): the colours' cotangent goes to band space through the
    transposed colour matrices, then one elementwise pass per chunk recomputes the layers
    and the stack and runs the chain rule back through them: the S and K cotangents
    through q (`_layer_SK`), two chunks a step side by side (`STREAMS`), the stack's
    adjoints divided, the S and K sums as products, and a layer absent from a whole chunk
    skipping its S and K sums. The gradient of the makeup face's render with respect to the
    thickness maps or the scalars then costs about two to three forward passes; JAX's own
    transpose of the chunked JVP costs more, reverse mode over checkpointed chunks of
    `_joint` several times more, and plain reverse mode through this forward (the `switch`
    inside a `map` keeps every branch's residuals) two orders of magnitude more and tens of
    GB. On a GPU (`_cpu_form`): the colours in one program and the loops in wide chunks,
    quicker there than the CPU's forms. The figures: benchmarks/RESULTS.md
    (benchmarks/bench_gradients.py).
    """
    args = (X, E, h, h_l, S, K, skin_R)
    if not _cpu_form("forward"):  # a GPU fuses the three products' shared work itself
        return _joint(grid, blurred, *args)
    return _forward_chunked(grid, blurred, *args)


@_colours.defjvp
def _colours_jvp(grid, blurred, primals, tangents):
    out = _colours(grid, blurred, *primals)
    return out, linear_call(*_rules(grid, blurred), tuple(primals), tuple(tangents))


def _per_texel(a, axis: int, P: int, chunk: int):
    """`a (..., P, ...)`, texels along `axis`, as `(chunks, ..., chunk, ...)`: the last chunk
    padded with zeros."""
    chunks = -(-P // chunk)
    widths = [(0, 0)] * a.ndim
    widths[axis] = (0, chunks * chunk - P)
    a = jnp.pad(a, widths)
    a = a.reshape(*a.shape[:axis], chunks, chunk, *a.shape[axis + 1:])
    return jnp.moveaxis(a, axis, 0)


def _chunked_tangent(grid, blurred, primals, tangents):
    """Forward mode: the tangent of the colours, a loop over chunks of texels (`CHUNK` on a
    CPU, else chunks of at most an eighth of `WIDE_CHUNK`: `jax.jacfwd` batches this
    function over every tangent, 21 for the makeup's scalars, multiplying each intermediate
    by as many), each chunk's tangent recomputed from its inputs (checkpointed)."""
    X = primals[0]
    P = X.shape[1]
    chunk = _chunking(P, WIDE_CHUNK // 8)[0]

    def per_texel(a, axis):
        return _per_texel(a, axis, P, chunk)

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
    return out_dot.reshape(-1, out_dot.shape[-1])[:P]


@functools.cache
def _rules(grid, blurred):
    """The colours' tangent (forward mode, `_chunked_tangent`) and its transpose (reverse
    mode, `_cotangents`, derived by hand) for `linear.linear_call`: linear in the tangents
    of `_colours`' seven inputs."""
    def tangent(*args):
        return _chunked_tangent(grid, blurred, args[:7], args[7:])

    def transpose(*args):
        return _cotangents_chunked(grid, blurred, *args)

    return tangent, transpose


def _band(g, M):
    """`g @ M.T` for `g (P, 3)`, `M (n, 3)`, written as three broadcast products so that it
    fuses into the elementwise pass that reads it: `(P, n)`."""
    M = jnp.asarray(M, g.dtype)
    return g[:, 0:1] * M[:, 0] + g[:, 1:2] * M[:, 1] + g[:, 2:3] * M[:, 2]


def _layer_SK(S, K, X, parts, aR, aT):
    """The cotangents of one KM layer's S and K `(n,)`, summed over texels, from the
    cotangents `aR, aT (P, n)` of its R0 and T and the intermediates of `km.layer_parts`.
    With q = β² = K(K + 2S), R0 = Sτ/D and T = sech z/D, D = (S + K)τ + 1, where τ and
    sech z depend on S and K through q only: the cotangent of q per texel and band is
    a_q = a_τ ∂τ/∂q + a_sech ∂sech/∂q with ∂τ/∂q = w/2, ∂sech z/∂q = −X τ sech z/2,
    w = (X sech² z − τ)/β² (= −X³ F(z²) sech² z for small z, F(y) = Σ_k≥1 4^k y^(k−1)/(2k+1)!,
    a series with no branch point at K = 0), and ∂q/∂S = 2K, ∂q/∂K = 2(K + S) are per band:
    so S and K are each one sum over texels of a short expression of the layer's own
    intermediates (rather than evaluating the layer again for its partials, with exp and
    three divisions, in each of the two sums)."""
    R, T, tau, sech, inv_den, small, qs, inv_beta = parts
    SK = S + K
    sech2 = sech * sech
    w = jnp.where(small, -(X * X * X) * km.horner(_F_SERIES, qs) * sech2,
                  (X * sech2 - tau) * (inv_beta * inv_beta))
    aR_d, aT_d = aR * inv_den, aT * inv_den
    a_q = 0.5 * ((aR_d * (S - R * SK) - aT_d * T * SK) * w - aT_d * X * sech * tau)
    a_S = tau * (aR_d * (1.0 - R) - aT_d * T)  # through S and S + K, τ held
    a_K = -tau * (aR_d * R + aT_d * T)
    return _colsum(a_S + (2.0 * K) * a_q), _colsum(a_K + (2.0 * SK) * a_q)


# F(y) = Σ_k≥1 4^k y^(k−1)/(2k+1)!, highest power first (Horner), for `_layer_SK`: at
# y = 0.25 the first dropped term is below 1e-16 relative.
_F_SERIES = [4.0 ** k / float(np.prod(np.arange(1, 2 * k + 2, dtype=np.float64)))
             for k in range(8, 0, -1)]


def _rowsum(a):
    """`a (P, n)` summed over bands, `(P, 1)`, as a product with ones: XLA:CPU fuses a
    reduction along the short band axis into the elementwise work and runs that loop
    unvectorised (the backward pass is markedly slower than with the product)."""
    if not _cpu_form("sums"):
        return jnp.sum(a, axis=-1, keepdims=True)
    return matmul(a, jnp.ones((a.shape[-1], 1), a.dtype))


def _colsum(a):
    """`a (P, n)` summed over texels, `(n,)`, as a product with ones: as a reduction along
    the texel axis (the major one) XLA:CPU fuses the summand into a loop that strides
    across it."""
    if not _cpu_form("sums"):
        return jnp.sum(a, axis=0)
    return matmul(jnp.ones((1, a.shape[0]), a.dtype), a)[0]


def _cotangents(grid, blurred, X, E, h, h_l, S, K, skin_R, g):
    """The reverse-mode derivative of `_colours` (its transpose), derived by hand: the
    cotangent `g (P, C)` of the colours, taken to band space by the transposed colour
    matrices, then one elementwise pass over (texel, band) that recomputes each KM layer,
    the stack and the highlights and accumulates the chain rule backwards through them.
    Returns the cotangents of `(X, E, h, h_l, S, K, skin_R)`, in their shapes."""
    n_layers = X.shape[0]
    dtype = X.dtype
    if blurred:
        gs = _band(g[:, :3], grid.rgb_matrix)
        ga = _band(g[:, 3:6], grid.xyz_matrix)
        gt = _band(g[:, 6:], grid.xyz_matrix)
    else:
        gs = _band(g, grid.rgb_matrix)
        ga = gt = E * gs
    s = skin_R
    x = [X[i][:, None] for i in range(n_layers)]  # (P, 1) each
    parts = [km.layer_parts(S[i], K[i], x[i]) for i in range(n_layers)]
    R, T = [p[0] for p in parts], [p[1] for p in parts]
    # The stack from the bottom up (km.stack's order), every partial stack kept.
    accs = [(R[0], T[0], R[0])]
    for i in range(1, n_layers):
        aR, aT, aRb = accs[-1]
        inv = 1.0 / (1.0 - R[i] * aR)
        accs.append((R[i] + T[i] * T[i] * aR * inv, T[i] * aT * inv,
                     aRb + aT * aT * R[i] * inv))
    Rt, Tt, Rbt = accs[-1]
    u = 1.0 / (1.0 - Rbt * s)
    da = s * ((Tt - 1.0) + Rbt * s) * u
    # a = s + da = s T u: da's partials ∂/∂T = s u, ∂/∂R' = s² T u², ∂/∂s = T u² − 1.
    A = ga + gt * (Tt - 1.0)  # the whole cotangent of da
    a_T = gt * (s + da) + A * s * u
    a_Rb = A * s * s * Tt * u * u
    a_s = gt * (Tt - 1.0) + A * (Tt * u * u - 1.0)
    a_R = gs * E
    dE = _rowsum(gs * Rt)
    if not blurred:
        dE = dE + _rowsum(gs * (da + (Tt - 1.0) * (s + da)))
    # Back through the stack (compose, R1' = R1 for a homogeneous top layer).
    aR_l, aT_l = [None] * n_layers, [None] * n_layers
    for i in range(n_layers - 1, 0, -1):
        cR, cT, _ = accs[i - 1]
        den = 1.0 - R[i] * cR
        den2 = den * den
        T2 = T[i] * T[i]
        # Divided by den, den², not multiplied by their inverses: XLA:CPU then keeps each
        # level's adjoints in memory (a division with several users is not recomputed),
        # where products would be recomputed inside every later consumer, the chain from the
        # top once per layer's ∂/∂X, ∂/∂S and ∂/∂K.
        aR_l[i] = (a_R * (den2 + T2 * cR * cR) + a_T * T[i] * cT * cR + a_Rb * cT * cT) / den2
        aT_l[i] = (2.0 * a_R * T[i] * cR + a_T * cT) / den
        a_R, a_T = ((a_R * T2 + a_T * T[i] * cT * R[i] + a_Rb * cT * cT * R[i] * R[i]) / den2,
                    (a_T * T[i] + 2.0 * a_Rb * cT * R[i]) / den)
    aR_l[0], aT_l[0] = a_R + a_Rb, a_T
    # The highlights: dD_i = dD_(i−1) T_i² + h (T_i² − 1) + cover_i h_l,i, from the bottom.
    D = [jnp.zeros_like(Rt)]
    for i in range(n_layers - 1):
        cover = -jnp.expm1(-x[i] / COVER_MM)
        T2 = T[i] * T[i]
        D.append(D[-1] * T2 + h * (T2 - 1.0) + cover * h_l[i])
    a_D = gs
    dh = 0.0
    dh_l, dX = [None] * n_layers, [None] * n_layers
    dS, dK = [None] * n_layers, [None] * n_layers
    for i in range(n_layers - 1, -1, -1):
        T2 = T[i] * T[i]
        aT_l[i] = aT_l[i] + 2.0 * a_D * (D[i] + h) * T[i]
        dh = dh + a_D * (T2 - 1.0)
        sum_D = _rowsum(a_D)  # (P, 1)
        cover = -jnp.expm1(-x[i] / COVER_MM)
        dh_l[i] = cover * sum_D
        # ∂R0/∂X = S T², ∂T/∂X = −T (S + K − S R0) (Kubelka–Munk's equations).
        dX[i] = (_rowsum(aR_l[i] * S[i] * T2 - aT_l[i] * T[i] * (S[i] + K[i] - S[i] * R[i]))
                 + h_l[i] * sum_D * (1.0 - cover) / COVER_MM)[:, 0]
        # A layer absent from every texel of the chunk (X = 0: τ = 0, so every term is
        # exactly 0) adds nothing to its S and K: the sums are skipped there. On the makeup
        # face 1.6 layers of 4 are present in a chunk on average, so the render's gradient
        # with respect to its scalars is quicker for it (benchmarks/RESULTS.md).
        layer_args = (S[i], K[i], x[i], parts[i], aR_l[i], aT_l[i])
        dS[i], dK[i] = jax.lax.cond(
            jnp.any(x[i] != 0), _layer_SK,
            lambda S_, K_, *_: (jnp.zeros_like(S_), jnp.zeros_like(K_)),
            *layer_args) if _cpu_form("skip") else _layer_SK(*layer_args)
        a_D = a_D * T2
    dh = _rowsum(dh)
    d_skin = a_s if skin_R.ndim == 2 else _colsum(a_s)
    return (jnp.stack(dX), dE, dh, jnp.stack(dh_l), jnp.stack(dS), jnp.stack(dK),
            d_skin.astype(dtype))


def _cotangents_chunked(grid, blurred, X, E, h, h_l, S, K, skin_R, g, chunk=None,
                        streams=None):
    """`_cotangents` in a loop over chunks of `chunk` texels (the last one padded), so that
    each chunk's pass stays in the cache; the per-band cotangents (S, K and a skin spectrum
    shared by all texels) summed over the chunks.

    Each step of the loop takes `streams` chunks and runs `_cotangents` on each apart: two
    programs with no data between them, which XLA:CPU's executor runs on two threads at
    once. With one chunk a step, about half of the pass's ~45 fusions (the exps, the
    divisions: cheap per byte) are too small for XLA to split across threads, and one
    core waited on the other: on 2 cores the pass took longer, relative to the three
    spectral products, than on one (benchmarks/RESULTS.md)."""
    P = X.shape[1]
    chunk = chunk or _chunking(P)[0]
    streams = streams or _chunking(P)[1]
    step = chunk * streams

    def per_texel(a, axis):
        return _per_texel(a, axis, P, step)

    def unchunk(a, axis):  # the inverse of per_texel, the padding dropped
        a = jnp.moveaxis(a, 0, axis)
        a = a.reshape(*a.shape[:axis], -1, *a.shape[axis + 2:])
        return jax.lax.slice_in_dim(a, 0, P, axis=axis)

    per = skin_R.ndim == 2
    local = (per_texel(X, 1), per_texel(E, 0), per_texel(h, 0), per_texel(h_l, 1),
             per_texel(skin_R, 0) if per else None, per_texel(g, 0))
    axes = (1, 0, 0, 1, 0, 0)  # each local argument's texel axis

    def one(c):
        parts = []
        for j in range(streams):  # independent: the executor runs them side by side
            x, e, hh, hl, sk, gg = (
                None if a is None else jax.lax.slice_in_dim(a, j * chunk, (j + 1) * chunk,
                                                            axis=ax)
                for a, ax in zip(c, axes, strict=True))
            parts.append(_cotangents(grid, blurred, x, e, hh, hl, S, K,
                                     sk if per else skin_R, gg))
        texel_axes = (1, 0, 0, 1, None, None, 0 if per else None)
        return tuple(jnp.concatenate(p, axis=ax) if ax is not None else sum(p)
                     for p, ax in zip(zip(*parts, strict=True), texel_axes, strict=True))

    dX, dE, dh, dh_l, dS, dK, dskin = jax.lax.map(one, local)
    return (unchunk(dX, 1), unchunk(dE, 0), unchunk(dh, 0), unchunk(dh_l, 1),
            dS.sum(0), dK.sum(0), unchunk(dskin, 0) if per else dskin.sum(0))
