"""The Kubelka–Munk core: exact limits, energy, an independent reference, gradients."""

import itertools

import jax
import jax.numpy as jnp
import mpmath as mp
import numpy as np
import pytest
from conftest import check_grads_scaled
from jax.test_util import check_grads

from jaxskin import km

mp.mp.dps = 40


def reference_layer(S, K, X):
    """Eq. 1–2 in 40-digit arithmetic, straight from the paper's sinh/cosh form."""
    S, K, X = mp.mpf(S), mp.mpf(K), mp.mpf(X)
    if K == 0:
        return S * X / (1 + S * X), 1 / (1 + S * X)
    if S == 0:
        return mp.mpf(0), mp.exp(-K * X)
    a = 1 + K / S
    b = mp.sqrt(a * a - 1)
    sh, ch = mp.sinh(b * S * X), mp.cosh(b * S * X)
    d = a * sh + b * ch
    return sh / d, b / d


def f64(*xs):
    return [jnp.asarray(x, jnp.float64) for x in xs]


# ---------------------------------------------------------------- values and limits


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_layer_matches_high_precision_reference(x64, dtype):
    """Relative error against mpmath over a log grid of S, K/S and S·X (incl. 0 and 1e4).

    Bound: 4 ulp × (1 + z), z = βX. The (1 + z) is the conditioning of T ~ exp(−z): an exact
    z rounded once to `dtype` already moves T by z ulp, so no implementation does better.
    """
    eps, tiny = np.finfo(dtype).eps, np.finfo(dtype).tiny
    worst = 0.0
    for S, ratio, SX in itertools.product(
        np.logspace(-4, 3, 8),
        [0, 1e-9, 1e-4, 0.1, 1, 10, 1e3, 1e6],
        [0, 1e-6, 1e-3, 0.1, 0.5, 1, 3, 10, 100, 1e4],
    ):
        # The reference sees the inputs as rounded to `dtype`: what is measured is the
        # algorithm's error, not the rounding of the inputs.
        s, k, x = (dtype(v) for v in (S, ratio * S, SX / S))
        ref = reference_layer(float(s), float(k), float(x))
        z = float(x) * np.sqrt(float(k) * (float(k) + 2 * float(s)))
        for g, r in zip(km.layer(*(jnp.asarray(v) for v in (s, k, x))), ref, strict=True):
            assert g.dtype == dtype
            r = float(r)
            if r > 100 * tiny:  # below that the true value is not representable
                worst = max(worst, abs(float(g) - r) / r / (1 + z) / eps)
            else:
                assert 0.0 <= float(g) <= 100 * tiny
    assert worst < 4, f"{worst:.2f} ulp x (1 + z)"


def test_layer_exact_limits(x64):
    S, X, K = f64([0.5, 3.0, 40.0], [0.2, 1.0, 5.0], [0.7, 2.0, 9.0])
    R0, T = km.layer(S, 0.0 * S, X)  # K -> 0
    np.testing.assert_allclose(R0, S * X / (1 + S * X), rtol=1e-15)
    np.testing.assert_allclose(T, 1 / (1 + S * X), rtol=1e-15)
    R0, T = km.layer(0.0 * S, K, X)  # S -> 0
    np.testing.assert_array_equal(R0, 0.0)
    np.testing.assert_allclose(T, np.exp(-K * X), rtol=1e-14)
    R0, T = km.layer(S, K, 0.0 * X)  # X -> 0
    np.testing.assert_array_equal(R0, 0.0)
    np.testing.assert_array_equal(T, 1.0)
    R0, T = km.layer(S, K, 1e6 + 0 * X)  # X -> infinity
    np.testing.assert_allclose(R0, km.r_inf(S, K), rtol=1e-15)
    np.testing.assert_array_equal(T, 0.0)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_layer_bounded_and_finite_at_extremes(x64, dtype):
    """[0, 1], R0 + T <= 1, no overflow for b·S·X up to 1e4 and far beyond."""
    S = np.logspace(-8, 6, 29, dtype=dtype)[:, None, None]
    ratio = np.array([0, 1e-9, 1e-3, 1, 1e3, 1e6], dtype)[None, :, None]
    SX = np.array([0, 1e-6, 1, 1e2, 1e4, 1e8], dtype)[None, None, :]
    R0, T = km.layer(S, ratio * S, SX / S)
    for v in (R0, T):
        assert v.dtype == dtype
        assert bool(jnp.all(jnp.isfinite(v))) and bool(jnp.all((v >= 0) & (v <= 1)))
    eps = np.finfo(dtype).eps
    assert bool(jnp.all(R0 + T <= 1 + 4 * eps))


def test_python_numbers_follow_jax_default_float(x64):
    """Python numbers alone take JAX's default float (float64 here, under x64), as
    `jnp.exp(1.0)` does; with a float32 array they follow it (once they were float32 even
    under x64, so a float64 check written with literals ran in float32: 3e-8 off)."""
    R0, T = km.layer(1.0, 0.5, 0.1)
    assert R0.dtype == jnp.float64 and T.dtype == jnp.float64
    assert km.r_inf(30.0, 2).dtype == jnp.float64
    assert km.layer(jnp.float32(1.0), 0.5, 0.1)[0].dtype == jnp.float32
    assert km.layer(np.float16(1.0), 0.5, 0.1)[0].dtype == jnp.float32  # at least float32
    # against the closed form with a = (S + K)/S, b = sqrt(a² − 1): R∞ = a − b
    a = (30.0 + 2.0) / 30.0
    assert abs(float(km.r_inf(30.0, 2.0)) - (a - np.sqrt(a * a - 1.0))) < 1e-15


def test_r_inf_and_inverse(x64):
    S, K = f64(np.logspace(-3, 3, 13), np.logspace(-6, 4, 13)[::-1])
    R = km.r_inf(S, K)

    def textbook(s, k):  # a − b in 40 digits; in float64 it cancels for large K/S
        a = 1 + mp.mpf(float(k)) / mp.mpf(float(s))
        return float(a - mp.sqrt(a * a - 1))

    np.testing.assert_allclose(R, [textbook(s, k) for s, k in zip(S, K, strict=True)], rtol=1e-14)
    np.testing.assert_allclose(km.ks_from_r_inf(R), K / S, rtol=1e-9)
    assert float(km.r_inf(*f64(2.0, 0.0))) == 1.0
    assert float(km.r_inf(*f64(0.0, 2.0))) == 0.0


def test_compose_black_backing_reflects_exactly_the_top_layer(x64):
    """The check that rules out Huang et al.'s misprinted eq. 3 (T1 R1 T1)."""
    R1, T1 = km.layer(*f64(4.0, 0.3, 0.2))
    R12, T12, _ = km.compose((R1, T1), (jnp.zeros(()), jnp.zeros(())))
    assert float(R12) == float(R1) and float(T12) == 0.0
    misprint = R1 + T1 * R1 * T1 / (1 - R1 * 0.0)
    assert float(misprint) != pytest.approx(float(R1))


def test_stack_is_associative_and_over_uses_the_back_reflectance(x64):
    """With R_back carried along, composition is exact for composites and associative; a
    composite of different layers reflects differently from below, which `over` needs."""
    rng = np.random.default_rng(0)
    S, K, X = f64(
        rng.uniform(0.1, 20, (3, 7)), rng.uniform(0, 5, (3, 7)), rng.uniform(0, 1, (3, 7))
    )
    R, T = km.layer(S, K, X)
    a, b, c = ((R[i], T[i]) for i in range(3))
    left = km.compose(km.compose(a, b), c)
    right = km.compose(a, km.compose(b, c))
    whole = km.stack(R, T)
    for x, y, z in zip(left, right, whole, strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-13)
        np.testing.assert_allclose(x, z, rtol=1e-13)
    assert not np.allclose(whole.R, whole.R_back)  # asymmetric, as it should be
    Rg = jnp.asarray(rng.uniform(0, 1, 7))
    with_ground = km.stack(jnp.concatenate([R, Rg[None]]), jnp.concatenate([T, 0 * Rg[None]]))
    np.testing.assert_allclose(
        km.over(whole.R, whole.T, Rg, whole.R_back), with_ground.R, rtol=1e-14
    )
    assert not np.allclose(km.over(whole.R, whole.T, Rg), with_ground.R)  # R_back matters
    assert bool(jnp.all(whole.R + whole.T <= 1 + 1e-12))
    assert bool(jnp.all(whole.R_back + whole.T <= 1 + 1e-12))


def test_stack_of_equal_layers_is_one_thick_layer(x64):
    """Physics, and a check of the fold: n layers of X/n are one layer of X."""
    S, K, X = f64([0.3, 5.0, 50.0], [1e-3, 1.0, 30.0], [0.05, 0.4, 2.0])
    R, T = km.layer(S, K, X / 4)
    Rs, Ts, Rb = km.stack(jnp.stack([R] * 4), jnp.stack([T] * 4))
    np.testing.assert_allclose(Rb, Rs, rtol=1e-13)  # equal layers: symmetric
    R1, T1 = km.layer(S, K, X)
    np.testing.assert_allclose(Rs, R1, rtol=1e-12)
    np.testing.assert_allclose(Ts, T1, rtol=1e-12)


def test_layer_of_two_halves_is_the_whole(x64):
    """Physics: a layer of thickness X is two layers of X/2 composed."""
    S, K, X = f64([0.3, 5.0, 50.0], [1e-3, 1.0, 30.0], [0.05, 0.4, 2.0])
    half = km.layer(S, K, X / 2)
    whole = km.compose(half, half)
    for x, y in zip(whole[:2], km.layer(S, K, X), strict=True):
        np.testing.assert_allclose(x, y, rtol=1e-12)


def test_jit_and_vmap(x64):
    S, K, X = f64(np.linspace(1, 2, 5), np.linspace(0, 1, 5), np.linspace(0, 3, 5))
    eager = km.layer(S, K, X)
    jitted = jax.jit(km.layer)(S, K, X)
    mapped = jax.vmap(km.layer)(S, K, X)
    for a, b, c in zip(eager, jitted, mapped, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-14)
        np.testing.assert_allclose(a, c, rtol=1e-14)


# ---------------------------------------------------------------- gradients

S_REF = 2.0
RATIOS = [0.0, 1e-9, 1e-2, 1.0, 1e3]  # K/S
SXS = [0.0, 1e-6, 0.3, 1.0, 10.0, 1e4]  # S·X


# The functions the gradient tests check, jitted once for the module: every point has the
# same shapes, so check_grads' programs (jvp, vjp and their second order) compile once, not
# op by op at each of the 30 points.
_layer = jax.jit(lambda s, k, x: jnp.stack(km.layer(s, k, x)))
_layer_flat = jax.jit(lambda a: jnp.stack(km.layer(*a)))
_over = jax.jit(km.over)
_r_inf = jax.jit(km.r_inf)


@jax.jit
def _stack_over(S, K, X):
    s = km.stack(*km.layer(S, K, X))
    return jnp.stack([*s, km.over(s.R, s.T, 0.45, s.R_back)])


@pytest.mark.parametrize("ratio, SX", list(itertools.product(RATIOS, SXS)))
def test_layer_gradients(x64, ratio, SX):
    args = f64(S_REF, ratio * S_REF, SX / S_REF)
    # Steps relative to each argument. At K = 0 the layer varies in K on the scale
    # 1/(S X²) (z² = X²K(K + 2S)); at X = 0, on the scale 1/S.
    K_natural = 1e-3 * S_REF / (1.0 + SX * SX)
    scales = [S_REF, max(ratio * S_REF, K_natural), max(SX, 1e-3) / S_REF]
    check_grads_scaled(_layer, args, scales)
    grads = jax.jacrev(_layer_flat)(jnp.stack(args))
    assert bool(jnp.all(jnp.isfinite(grads)))


@pytest.mark.parametrize("ratio", [1e-9, 1e-2, 1.0, 1e3])
def test_r_inf_gradients(x64, ratio):
    # Steps relative to K stay inside K > 0, where R∞ is analytic (branch point at K = 0).
    check_grads_scaled(_r_inf, f64(S_REF, ratio * S_REF), [S_REF, ratio * S_REF])


def test_r_inf_gradient_at_k_zero(x64):
    """At K = 0: ∂R∞/∂S = 0 exactly (finite), ∂R∞/∂K = −∞ (the true branch point)."""
    S, K = f64(S_REF, 0.0)
    check_grads(lambda s: km.r_inf(s, K), (S,), order=2, modes=("fwd", "rev"))
    dS, dK = jax.grad(km.r_inf, argnums=(0, 1))(S, K)
    assert float(dS) == 0.0
    assert float(dK) == -np.inf


@pytest.mark.parametrize(
    "R0, T, Rg",
    [(0.3, 0.5, 0.4), (0.0, 1.0, 0.5), (0.2, 0.0, 0.9), (0.6, 0.3, 0.0), (0.5, 0.5, 0.999)],
)
def test_over_gradients(x64, R0, T, Rg):
    check_grads(_over, f64(R0, T, Rg), order=2, modes=("fwd", "rev"), eps=1e-6)


@pytest.mark.parametrize("ratio, SX", [(1.0, 1.0), (0.0, 0.0), (1e-9, 1e4), (1e3, 1e-6)])
def test_stack_gradients_through_layers(x64, ratio, SX):
    """Gradient of a 3-layer stack over skin w.r.t. every S, K and thickness."""
    base = f64([S_REF, 5.0, 0.5], [ratio * S_REF, 1.0, 2.0], [SX / S_REF, 0.1, 0.3])
    K_natural = 1e-3 * base[0] / (1.0 + (base[0] * base[2]) ** 2)  # see test_layer_gradients
    scales = [base[0], jnp.maximum(base[1], K_natural), jnp.maximum(base[2], 1e-3)]
    check_grads_scaled(_stack_over, base, scales)


@pytest.mark.parametrize("dtype, X", [(jnp.float32, 2e19), (jnp.float32, 1e30),
                                      (jnp.float64, 1e160)])
def test_layer_gradient_is_r_infs_at_a_thickness_whose_square_overflows(x64, dtype, X):
    """Past X ~ 2e19 mm (float32; 1e155 in float64) X² overflows in a branch test, and its
    derivative would make ∂R0/∂S, ∂R0/∂K NaN while the values are right. There the layer
    is R∞'s: its gradient, by autodiff of the closed form
    S / (S + K + sqrt(K² + 2KS)); T and its gradient 0. Measured: equal to 1e-7."""
    S, K = jnp.asarray(30.0, dtype), jnp.asarray(2.0, dtype)
    gR = jax.grad(lambda s, k: km.layer(s, k, jnp.asarray(X, dtype))[0], (0, 1))(S, K)
    gT = jax.grad(lambda s, k: km.layer(s, k, jnp.asarray(X, dtype))[1], (0, 1))(S, K)
    want = jax.grad(lambda s, k: s / (s + k + jnp.sqrt(k * k + 2 * k * s)), (0, 1))(S, K)
    np.testing.assert_allclose(np.array(gR), np.array(want), rtol=1e-5)
    assert np.all(np.array(gT) == 0)


def test_a_stack_laid_out_texels_first_is_warned_about():
    """A (cases, layers) array given to km.stack composed one "layer" per case: the
    stability sweep's 3-layer stack over 108 cases was a 108-layer stack over 3 (its
    gradient took two minutes to compile). More than MANY_LAYERS layers is warned about;
    the layered order is silent."""
    import warnings

    R, T = jnp.full((3, 108), 0.2), jnp.full((3, 108), 0.7)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert km.stack(R, T).R.shape == (108,)
    with pytest.warns(UserWarning, match=r"km.stack: 108 layers along the leading axis "
                                         r"\(shape \(108, 3\)\).*wants .T"):
        km.stack(R.T, T.T)


def test_float64_tiny_k_and_huge_thickness_takes_the_right_branch(x64):
    """X must not be clamped to 1e15 for the branch test in float64: at K = 1e-40, X = 1e20
    (z ~ 1.4) the series branch would give T = 1.0e-20 for 7.3e-21 (mpmath's value)."""
    R, T = km.layer(*f64(1.0, 1e-40, 1e20))
    R_ref, T_ref = reference_layer(1.0, 1e-40, 1e20)
    assert float(T) == pytest.approx(float(T_ref), rel=1e-12)  # measured 7.3e-21 both
    assert float(R) == pytest.approx(float(R_ref), rel=1e-12)


@pytest.mark.parametrize("call, words", [
    (lambda: km.stack(jnp.zeros((0, 3)), jnp.zeros((0, 3))), "at least one layer"),
    (lambda: km.stack(0.2, 0.3), "at least one layer"),
    (lambda: km.compose((0.2,), (0.1, 0.2)), r"a layer is \(R, T\) or \(R, T, R_back\), got 1"),
])
def test_malformed_stacks_are_named(call, words):
    """Named as a ValueError, not an IndexError, a tuple index error or an unpacking
    error."""
    with pytest.raises(ValueError, match=words):
        call()
