"""Gradient coverage (issue 20, item 3): `check_grads` in float64, modes fwd and rev, order
1, for the differentiable functions the rest of the suite did not check, at ordinary and
stiff points. Small sizes throughout: each test takes seconds."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin import formats, km, raster, render, skin, spectral, sss, view, wrinkles
from jaxskin.scene import load_scene
from jaxskin.shading import blinn, kelemen, layered


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


GRID = spectral.Grid(step=20)

# ------------------------------------------------------------------ small functions


@pytest.mark.parametrize("R", [[0.5, 0.9], [1e-4, 0.999999], [0.03, 1.0]])
def test_ks_from_r_inf(x64, R):
    R = np.asarray(R)
    check_grads_scaled(km.ks_from_r_inf, [R], [R * 1e-2], order=1)


def test_to_xyz(x64):
    spectra = np.random.default_rng(2).uniform(0, 1, (3, 4, len(GRID)))
    check_grads_scaled(lambda s: spectral.to_xyz(s, GRID), [spectra], [1.0], order=1)


@pytest.mark.parametrize("melanin", [0.0, 0.7, 20.0])
def test_skin_reflectance(x64, melanin):
    base = formats.nist_reflectance(7, GRID)
    check_grads_scaled(lambda b, m: skin.reflectance(b, m, GRID), [base, melanin],
                       [0.01, 0.01], order=1)


@pytest.mark.parametrize("x", [[0.01, 0.18, 0.5, 0.9, 1.3], [0.0031, 0.0032, -0.2, 1e-5, 0.003]],
                         ids=["curve", "near the joint"])
def test_encode_srgb(x64, x):
    """Both pieces and either side of 0.0031308 (steps of 1e-7 stay on one side)."""
    x = np.asarray(x)
    check_grads_scaled(render.encode_srgb, [x], [1e-7 * np.ones_like(x)], order=1, eps=1.0,
                       rtol=1e-6)


def test_k_noise_and_the_noisy_height(x64):
    rng = np.random.default_rng(3)
    h, r = rng.uniform(0.5, 1.0, (6, 7)), rng.uniform(0, 1, (6, 7))
    mask = np.ones((6, 7), bool)
    mask[0] = False
    check_grads_scaled(lambda h_, k: wrinkles.add_noise(h_, mask, k, r), [h, 0.3], [0.1, 0.1],
                       order=1)


def test_raster_interpolate(x64):
    xy = np.array([[0.3, 0.2], [9.6, 1.1], [4.2, 8.7], [9.9, 9.8]])
    faces = np.array([[0, 1, 2], [1, 3, 2]])
    r = raster.rasterize(xy, faces, 10, 10)
    attributes = np.random.default_rng(4).uniform(-1, 1, (4, 3))
    check_grads_scaled(lambda a: raster.interpolate(a, faces, r, empty=-2.0), [attributes],
                       [1.0], order=1)


def test_sample_without_wrap_and_downsample(x64):
    rng = np.random.default_rng(5)
    tex = rng.uniform(-1, 9, (6, 4, 2))  # outside the image too: clamped
    mask = np.ones((6, 4), bool)
    mask[1, 1] = False
    image = rng.uniform(0, 1, (8, 8, 3))
    check_grads_scaled(jax.jit(lambda im: view.downsample(view.sample(im, tex, mask, False), 2)),
                       [image], [1.0], order=1)


# ------------------------------------------------------------------ shading extremes


# Jitted once for the module (the fixed vectors arguments, not constants): check_grads'
# programs compile once for all the points of a test, not op by op.
_kelemen = jax.jit(lambda n, l_, v, r: kelemen.specular(n, l_, v, r, 0.18))
_blinn = jax.jit(lambda n, l_, v, s: blinn.shade(n, l_, v, 0.2, 0.5, 0.2, s))


@pytest.mark.parametrize("case", ["near the cut-off", "roughness 0.02", "roughness 0.005"])
def test_kelemen_extremes(x64, case):
    """cos α = N·H just above the 1e-4 cut-off (P_H underflows to 0, gradient finite and
    0), and nearly mirror-like roughness at a half vector 0.5° off the normal."""
    N = np.array([0.0, 0.0, 1.0])
    if case == "near the cut-off":  # both above the surface, N·H = 1.17e-4
        L, V = unit([1.0, 0.3, 1e-4]), unit([0.2, 1.0, 1e-4])
        assert 1e-4 < float(N @ unit(L + V)) < 1.2e-4
        m = 1.0
    else:
        L, V = unit([np.tan(np.radians(0.5)) * 2, 0, 1.0]), N
        m = float(case.split()[1])
    check_grads_scaled(lambda n, l_, r: _kelemen(n, l_, V, r), [N, L, m],
                       [1e-4, 1e-4, m * 1e-3], order=1, eps=1e-3)


@pytest.mark.parametrize("shininess", [1e-3, 0.5, 3e4])
def test_blinn_shininess_extremes(x64, shininess):
    N, V = unit([0.0, 0.1, 1.0]), unit([0.2, 0.0, 1.0])
    L = unit([-0.1, -0.05, 1.0]) if shininess > 1 else unit([0.7, 0.2, 0.5])
    check_grads_scaled(lambda n, l_, s: _blinn(n, l_, V, s), [N, L, shininess],
                       [1e-4, 1e-4, shininess * 1e-3], order=1, eps=1e-3)


@pytest.mark.parametrize("texel_mm", [0.05, 0.3, 2.0])
def test_sss_blur_across_texel_sizes(x64, texel_mm):
    """At 0.05 mm the widest Gaussian spans a 437-texel kernel; at 2 mm the narrow ones are
    far below a texel (each normalised on the grid)."""
    rng = np.random.default_rng(6)
    E = rng.uniform(0, 1, (9, 11, 3))
    mask = np.ones((9, 11), bool)
    mask[:, :2] = False
    check_grads_scaled(jax.jit(lambda e: sss.blur(e, texel_mm, mask)), [E], [1.0], order=1)


# ------------------------------------------------------------------ layered radiance


def _layers(P, rng):
    """Three layers on P texels: S, K per mm on GRID, thickness maps X (3, P) in mm."""
    n = len(GRID)
    S = rng.uniform(5, 60, (3, n))
    K = rng.uniform(0.5, 30, (3, n))
    X = rng.uniform(0, 0.03, (3, P))
    X[0, :5] = 0.0  # no foundation on a few texels
    return S, K, X


def test_radiance_of_bare_skin(x64):
    """No layers (no KM work): N, L, V, ambient and light, the skin spectrum, its Kelemen
    roughness and intensity."""
    P = 6
    N = np.stack([unit([0.1 * i - 0.2, 0.05 * i, 1.0]) for i in range(P)])
    L, V = unit([0.3, 0.2, 1.0]), unit([-0.2, 0.1, 1.0])

    def f(N, L, V, ambient, light, skin_R, m_s, rho_s):
        return layered.radiance(GRID, N, L, V, ambient, light, skin_R, m_s, rho_s)

    args = [N, L, V, 0.3, 0.7, formats.nist_reflectance(3, GRID), 0.3, 0.18]
    check_grads_scaled(jax.jit(f), args, [1e-3, 1e-3, 1e-3, 0.01, 0.01, 0.01, 0.01, 0.01],
                       order=1)


@pytest.mark.parametrize("blurred", [False, True], ids=["unblurred", "blurred"])
def test_radiance_through_the_chunked_jvp(x64, blurred):
    """Three layers through the makeup gradient's own rule (`layered._colours`' custom JVP,
    chunks of 1000 texels, two a step) on 2500 texels: a full step, then a ragged chunk of
    500 beside one of padding only, with and without SSS; with respect to N, L, V, ambient and light, the skin spectrum and its
    highlight, the thickness maps, S, K and the layers' roughness and intensity."""
    assert layered.CHUNK == 1000 and layered.STREAMS == 2
    rng = np.random.default_rng(8)
    side = 50
    P = side * side
    S, K, X = _layers(P, rng)
    N = np.zeros((P, 3))
    N[:, 2] = 1.0
    N[:, 0] = np.linspace(-0.3, 0.3, P)
    N /= np.linalg.norm(N, axis=1, keepdims=True)
    L, V = unit([0.3, 0.2, 1.0]), unit([-0.1, 0.05, 1.0])
    blur = None
    if blurred:
        def blur(colour):
            return sss.blur(colour.reshape(side, side, 3), 0.5).reshape(P, 3)

    def f(N, L, V, ambient, light, skin_R, m_s, rho_s, X, S, K, m, rho):
        return layered.radiance(GRID, N, L, V, ambient, light, skin_R, m_s, rho_s, S=S, K=K,
                                X=X, roughness=m, rho=rho, blur=blur)

    args = [N, L, V, 0.3, 0.7, formats.nist_reflectance(3, GRID), 0.3, 0.18, X, S, K,
            np.array([0.4, 0.25, 0.2]), np.array([0.1, 0.2, 0.3])]
    scales = [1e-3, 1e-3, 1e-3, 0.01, 0.01, 0.01, 0.01, 0.01, 1e-3, 0.5, 0.5, 0.01, 0.01]
    check_grads_scaled(jax.jit(f), args, scales, order=1)


# ------------------------------------------------------------------ the perspective render


def _float64(tree):
    return jax.tree.map(lambda a: jnp.asarray(a, jnp.float64)
                        if jnp.issubdtype(jnp.asarray(a).dtype, jnp.floating) else a, tree)


def test_perspective_render(x64):
    """A whole perspective Blinn render (a view direction per pixel, perspective-correct
    texture coordinates), float64: light direction, ambient and shininess."""
    sc = load_scene("hand", ["texture.size=48", "camera.size=16",
                             "camera.projection=perspective", "camera.rotate=[15.0, 10.0, 0.0]",
                             "wrinkles.enabled=false"])
    arrays = _float64(render.prepare(sc.config).arrays)
    assert "positions" in arrays
    params = _float64(sc.params)
    keys = ["light.direction", "light.ambient", "material.shininess"]

    def f(*values):
        p = {**params, **dict(zip(keys, values, strict=True))}
        return render.render_prepared(sc.config, p, arrays)

    values = [params[k] for k in keys]
    check_grads_scaled(jax.jit(f), values, [1e-3, 0.01, 0.5], order=1)
