"""Kubelka–Munk layers: reflectance and transmittance of a layer, a stack, a background.

Huang et al. 2013 eq. 1–2 (one layer) and the corrected eq. 3–4 (Kubelka's two-layer
formula; the paper prints T1 R1 T1 where T1 R2 T1 is meant — see
`shared/reference/constants.md`). S and K are per millimetre, thicknesses in millimetres.
Inversions: K/S from R∞ (`ks_from_r_inf`), R∞ and S·X of a film from its reflectance over
two backgrounds (Kubelka 1948, `two_backgrounds`); Saunderson's surface correction
(`saunderson`, `saunderson_inverse`) between an instrument's reading and the internal
reflectance the layer model describes.

Every function is elementwise over broadcastable arrays of any shape, follows the dtype of
its inputs (float32 at least: float16 and integers compute in float32), and is jit-, vmap-
and grad-safe, including at the limits K → 0, S → 0, X → 0 and X → ∞ (see `layer`).
"""

from __future__ import annotations

import warnings
from typing import NamedTuple

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

__all__ = ["Slab", "compose", "horner", "ks_from_r_inf", "layer", "layer_parts", "over",
           "r_inf", "saunderson", "saunderson_inverse", "stack", "two_backgrounds"]

# Below this value of z² = (βX)² the layer uses power series in z² (no square root, so the
# branch point at K = 0 has finite derivatives); above it, tanh/sech of z.
_Q_SMALL = 0.25
# Taylor coefficients in q = z² of sinh(z)/z and cosh(z), highest power first (Horner).
# At q = 0.25 the first dropped terms are below 1e-16 relative.
_SINHC = [1.0 / _f for _f in (1307674368000.0, 6227020800.0, 39916800.0, 362880.0, 5040.0,
                              120.0, 6.0, 1.0)]
_COSH = [1.0 / _f for _f in (20922789888000.0, 87178291200.0, 479001600.0, 3628800.0, 40320.0,
                             720.0, 24.0, 2.0, 1.0)]


def horner(coefficients, q):
    """The polynomial with `coefficients` (highest power first) at `q`, by Horner's rule:
    the series of `layer`'s small-z branch and of its hand-written derivative
    (`shading.layered`). Elementwise over `q`; the result has `q`'s shape and dtype."""
    out = jnp.full_like(q, coefficients[0])
    for c in coefficients[1:]:
        out = out * q + c
    return out


def layer(
    S: Float[ArrayLike, "*shape"],
    K: Float[ArrayLike, "*shape"],
    X: Float[ArrayLike, "*shape"],
) -> tuple[Float[Array, "*shape"], Float[Array, "*shape"]]:
    """Reflectance R0 (over black) and transmittance T of one Kubelka–Munk layer.

    Huang et al. 2013 eq. 1–2, rewritten without overflow: with β = sqrt(K(K + 2S)) and
    z = βX, dividing numerator and denominator of eq. 1–2 by β cosh z gives

        R0 = S τ / ((S + K) τ + 1),   T = sech z / ((S + K) τ + 1),   τ = tanh(z) / β.

    τ and sech z are even in β, so for small z they are evaluated as series in z² and the
    square root never meets its branch point: values and gradients are finite and exact at
    K = 0 (R0 = SX/(1 + SX)), S = 0 (T = exp(−KX)), X = 0 (R0 = 0, T = 1), and large z
    (R0 → R∞, T → 0, no overflow for any finite z). Always 0 <= R0, T and R0 + T <= 1.
    Work that depends on S and K only is done on their own shapes (per layer and band in a
    render), and the per-texel part costs one exp. Float32 limits, far outside physical
    values (per mm, S and K of 1e-3 to 1e5; X under a metre): K(K + 2S) overflows past
    ~1e38 (R0 and T come out 0), and the S, K gradient overflows where K(K + 2S) < ~1e-26
    with X > ~1e12 mm; float64 has neither within its range.

    **Arguments:**

    - `S`: scattering coefficient per mm, >= 0.
    - `K`: absorption coefficient per mm, >= 0.
    - `X`: thickness in mm, >= 0 and finite.

    **Returns:** `(R0, T)`, broadcast to a common shape.
    """
    S, K, X = _promote(S, K, X)
    return layer_parts(S, K, X)[:2]


def layer_parts(S, K, X):
    """`layer`'s R0 and T with the intermediates a hand-written derivative reuses
    (`shading.layered`'s cotangents): `(R0, T, τ, sech z, 1/D, small, z² where small,
    1/β)`, D = (S + K)τ + 1, `small` where the series branch is taken.

    **Arguments:** `S`, `K`, `X` as for `layer`, but already arrays of one floating dtype
    (`layer` promotes them first; this does not)."""
    # What depends on S and K only stays on their (small) shapes: in a render S, K are per
    # (layer, wavelength) and X per texel, so this is hoisted out of the per-texel work.
    q = K * (K + 2.0 * S)  # β²
    inv_beta = jax.lax.rsqrt(jnp.where(q > 0, q, 1.0))  # safe: only read where z² >= 0.25
    SK = S + K
    # X clamped where only the branch test and the series see it: X² overflows float32 at
    # X ~ 2e19 mm, and inf·0 in its derivative would make the gradient NaN there (the
    # values hold). Float64 clamps at 1e75 (X² ~ 1e150), not 1e15: at 1e15 the series would
    # be taken at K = 1e-40, X = 1e20 (z ~ 1.4), T 1.0e-20 for mpmath's 7.3e-21.
    Xc = jnp.minimum(X, 1e15 if X.dtype.itemsize < 8 else 1e75)
    z2 = q * (Xc * Xc)
    small = z2 < _Q_SMALL
    # Series branch (double-`where`: the unused branch sees harmless values).
    qs = jnp.where(small, z2, 0.0)
    inv_cosh = 1.0 / horner(_COSH, qs)
    tau_s = X * horner(_SINHC, qs) * inv_cosh
    # Large-z branch: one exp; at z >= 0.5, 1 − e² has no cancellation.
    e = jnp.exp(-X / inv_beta)
    e2 = e * e
    inv = 1.0 / (1.0 + e2)
    tau = jnp.where(small, tau_s, (1.0 - e2) * inv * inv_beta)
    sech = jnp.where(small, inv_cosh, 2.0 * e * inv)
    inv_den = 1.0 / (SK * tau + 1.0)
    return S * tau * inv_den, sech * inv_den, tau, sech, inv_den, small, qs, inv_beta


def r_inf(S: Float[ArrayLike, "*shape"], K: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """Reflectance of an opaque layer, R∞ = a − b = S / (S + K + sqrt(K² + 2KS)).

    Needs S + K > 0. R∞ has a square-root branch point at K = 0: ∂R∞/∂K = −∞ there (it is
    the physics, not the numerics), while ∂R∞/∂S stays finite (0). The root is written as
    sqrt(K)·sqrt(K + 2S) so that the S-derivative at K = 0 is exactly 0 instead of NaN.
    Fits parametrise by log K, where ∂R∞/∂log K → 0 as K → 0.

    **Arguments:**

    - `S`: scattering per mm, >= 0.
    - `K`: absorption per mm, >= 0.

    **Returns:** R∞ in [0, 1].
    """
    S, K = _promote(S, K)
    return S / (S + K + jnp.sqrt(K) * jnp.sqrt(K + 2 * S))


def ks_from_r_inf(R_inf: Float[ArrayLike, "*shape"]) -> Float[Array, "*shape"]:
    """The inverse of `r_inf`: K/S = (1 − R∞)² / (2 R∞), for R∞ in (0, 1]."""
    (R,) = _promote(R_inf)
    return (1.0 - R) ** 2 / (2.0 * R)


def two_backgrounds(
    R_black: Float[ArrayLike, "*shape"],
    R_white: Float[ArrayLike, "*shape"],
    Rg_black: Float[ArrayLike, "*shape"],
    Rg_white: Float[ArrayLike, "*shape"],
) -> tuple[Float[Array, "*shape"], Float[Array, "*shape"]]:
    """R∞ and S·X of a film from its reflectance over two backgrounds (Kubelka 1948).

    A film over a background Rg reflects R with b coth(bSX) = (1 + R Rg − a (R + Rg)) /
    (R − Rg), a = ½(R∞ + 1/R∞), b = √(a² − 1) (`constants.md`, Kubelka–Munk). The film is
    the same over both parts of a contrast card, so equating the two right-hand sides, which
    are linear in a, gives

        a = ½ [(1 + R_w Rg_w)(R_b − Rg_b) − (1 + R_b Rg_b)(R_w − Rg_w)] / (R_b Rg_w − R_w Rg_b).

    Then R∞ = 1 / (a + b) (= a − b without its cancellation at large a), and
    bSX = L(R_b) − L(Rg_b), L(R) = ½ ln|(1/R∞ − R) / (R∞ − R)| (the logarithmic form of
    Huang et al. eq. 6, no arcoth of an argument near 1); K·X = S·X (a − 1). Both
    backgrounds give the same S·X, since a was chosen so.

    Exact for readings the model produces; NaN where the readings lie outside its domain:
    a < 1 (noise, or a film over black brighter than over white), a denominator of 0 (two
    equal backgrounds, or a film that does not change either reading), or R_b not between
    Rg_b and R∞. An opaque film (R_b = R_w = R∞) gives its R∞ and S·X = inf: only K/S is
    known. Values and gradients are finite inside the domain (double-`where`).

    **Arguments:** reflectances in [0, 1] of the film over the black and the white
    background, and of the two backgrounds alone (Rg_black < Rg_white).

    **Returns:** `(R_inf, SX)`: the film's R∞ and S·X (per film, not per mm: divide by its
    thickness); its K·X is SX · `ks_from_r_inf(R_inf)`.
    """
    Rb, Rw, Gb, Gw = _promote(R_black, R_white, Rg_black, Rg_white)
    den = Rb * Gw - Rw * Gb
    num = (1.0 + Rw * Gw) * (Rb - Gb) - (1.0 + Rb * Gb) * (Rw - Gw)
    ok = den != 0
    a = 0.5 * num / jnp.where(ok, den, 1.0)
    ok = ok & (a > 1.0)
    a = jnp.where(ok, a, 2.0)
    b = jnp.sqrt((a - 1.0) * (a + 1.0))
    R_inf = 1.0 / (a + b)
    inv = 1.0 / R_inf

    def L(R):
        return 0.5 * jnp.log(jnp.abs((inv - R) / (R_inf - R)))

    # R_b strictly between Rg_b and R∞. Opaque: the film reads the same over both
    # backgrounds (then a = (R + 1/R)/2 exactly, R∞ = R_b; the recomputed R∞ is rarely
    # bit-equal to R_b, so the readings decide), S·X = inf.
    opaque = Rb == Rw
    inside = ((Rb - Gb) * (R_inf - Rb) > 0) & ~opaque
    Rb_safe = jnp.where(inside, Rb, 0.5 * (Gb + R_inf))
    SX = jnp.where(opaque, jnp.inf, (L(Rb_safe) - L(Gb)) / b)
    good = ok & (inside | opaque)
    nan = jnp.full_like(SX, jnp.nan)
    return jnp.where(good, jnp.where(opaque, Rb, R_inf), nan), jnp.where(good, SX, nan)


def saunderson(R: Float[ArrayLike, "*shape"], k1, k2) -> Float[Array, "*shape"]:
    """Saunderson's surface correction (Allen 1980): the reflectance an instrument reads
    (specular included) from the body's internal reflectance R,
    R_m = k1 + (1 − k1)(1 − k2) R / (1 − k2 R). k1: the surface's external reflection
    (≈ 0.04 for n = 1.5 with the specular component included; 0 excluded), k2: its internal
    reflection of diffuse light (≈ 0.4–0.6). k1 = k2 = 0 returns R exactly."""
    R, k1, k2 = _promote(R, k1, k2)
    return k1 + (1.0 - k1) * (1.0 - k2) * R / (1.0 - k2 * R)


def saunderson_inverse(R_m: Float[ArrayLike, "*shape"], k1, k2) -> Float[Array, "*shape"]:
    """The inverse of `saunderson`: R = (R_m − k1) / (1 − k1 − k2 + k2 R_m), the internal
    reflectance KM describes from an instrument's reading R_m (below 0 where R_m < k1: a
    reading darker than the surface alone, which the model cannot produce)."""
    R, k1, k2 = _promote(R_m, k1, k2)
    return (R - k1) / ((1.0 - k1) * (1.0 - k2) + k2 * (R - k1))


class Slab(NamedTuple):
    """Reflectance from above `R`, transmittance `T` (the same both ways) and reflectance
    from below `R_back` of a layer or a stack. One homogeneous layer has R_back = R."""

    R: Array
    T: Array
    R_back: Array


def compose(top, bottom) -> Slab:
    """Kubelka's rule for `top` lying on `bottom` (the corrected Huang et al. eq. 3–4).

        R = R1 + T1² R2 / (1 − R1' R2),   T = T1 T2 / (1 − R1' R2),
        R' = R2' + T2² R1' / (1 − R1' R2)

    where ' marks reflectance seen from below. For a homogeneous top (R1' = R1) this is
    eq. 3–4 as corrected; with a black backing (R2 = 0) the pair reflects exactly R1. Keeping
    R' makes the rule exact for composites too, and associative.

    **Arguments:**

    - `top`, `bottom`: `(R, T)` for one homogeneous layer, or `(R, T, R_back)` / a `Slab`.

    **Returns:** the `Slab` of the pair. Needs R1' R2 < 1.
    """
    R1, T1, R1b = _slab(top)
    R2, T2, R2b = _slab(bottom)
    inv = 1.0 / (1.0 - R1b * R2)
    return Slab(R1 + T1 * T1 * R2 * inv, T1 * T2 * inv, R2b + T2 * T2 * R1b * inv)


def over(R, T, Rg, R_back=None):
    """Reflectance of a layer or stack `(R, T)` over an opaque background of reflectance `Rg`.

    R + T² Rg / (1 − R_back Rg): `compose` with a bottom that transmits nothing. `R_back`
    (reflectance from below) defaults to `R`, exact for one homogeneous layer; for a stack
    pass `stack(...).R_back`. Needs R_back Rg < 1: a thick layer that absorbs nothing
    (R → 1) over a white background (Rg = 1) divides by zero, where the physical limit is 1.
    """
    top = (R, T) if R_back is None else (R, T, R_back)
    return compose(top, (Rg, jnp.zeros_like(jnp.asarray(Rg))))[0]


# More layers than this in `stack` is most likely an array laid out (texels, layers): a
# benchmark's 3-layer stack over 108 cases composed 108 layers, two minutes to compile.
MANY_LAYERS = 16


def stack(R: Float[ArrayLike, " layers *shape"], T: Float[ArrayLike, " layers *shape"]) -> Slab:
    """A stack of homogeneous layers (leading axis: layers, top first) as one `Slab`.

    Folds `compose` over the layers; the number of layers is static, so the loop unrolls.

    Performance note (XLA on CPU): a jitted function that returns several of R, T and R_back
    makes XLA materialise the work they share as full-size arrays; one that returns one array
    (e.g. `over(...)` of the stack on skin) fuses into a single loop. 1024² × 41 bands × 3
    layers: over skin 136 ms, R and T from one program 929 ms, as two programs 238 ms
    (benchmarks/RESULTS.md).

    **Returns:** `Slab(R, T, R_back)` of the whole stack, each of shape `*shape`.
    """
    R, T = _promote(R, T)
    if min(R.ndim, T.ndim) == 0 or min(R.shape[0], T.shape[0]) == 0:
        raise ValueError(f"km.stack: R {R.shape} and T {T.shape} need at least one layer "
                         "along the leading axis (layers first, top first)")
    if R.shape[0] > MANY_LAYERS:  # (texels, layers) for (layers, texels): 108 "layers"
        warnings.warn(f"km.stack: {R.shape[0]} layers along the leading axis (shape "
                      f"{R.shape}), each unrolled into the program; the layers go first, "
                      "top first (a (texels, layers) array wants .T)", stacklevel=2)
    acc = Slab(R[-1], T[-1], R[-1])
    for i in range(R.shape[0] - 2, -1, -1):
        acc = compose((R[i], T[i]), acc)
    return acc


def _slab(x):
    if len(x) not in (2, 3):
        raise ValueError(f"km.compose: a layer is (R, T) or (R, T, R_back), got {len(x)} "
                         "arrays")
    if len(x) == 2:
        R, T = _promote(*x)
        return R, T, R
    return _promote(*x)


def _promote(*xs):
    """Arrays of one floating dtype: the inputs' own (at least float32) if any is a floating
    array; for Python numbers alone JAX's default float (float64 under `jax_enable_x64`,
    so that a float64 check written with literals is not quietly float32)."""
    arrays = [jnp.asarray(x) for x in xs]
    dtype = jnp.result_type(*arrays)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    return [a.astype(jnp.promote_types(dtype, jnp.float32)) for a in arrays]
