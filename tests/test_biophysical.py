"""The biophysical skin model (`jaxskin.biophysical`): published numbers, KM limits, the range
of human skin, gradients, per-texel maps, and its place in scenes and renders."""

import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin import biophysical as bp
from jaxskin import formats, render, spectral
from jaxskin.scene import BIOPHYSICAL_KEYS, load_scene

WL = np.array([420.0, 500.0, 542.0, 576.0, 650.0, 700.0])


def chrom(wl=WL):
    return bp.chromophores(wl, formats.haemoglobin_table())


def f64(skin):
    return bp.Skin(*(jnp.asarray(v, jnp.float64) for v in skin))


# --- Absorption and scattering against the published formulas, evaluated by hand.

def test_melanin_and_baseline_against_hand_computed_values():
    # By hand, λ = 500 nm: ln 500 = 6.2146081; eumelanin 6.6e11 · e^(−3.33 · 6.2146081)
    # = 6.6e11 · e^−20 · e^−0.69465 = 6.6e11 · 2.06115e-9 · 0.49925 = 679.16 /cm = 67.916
    # /mm; pheomelanin 2.9e15 · e^(−29.51939) = 2.9e15 · 2.5437e-13 · 0.59488 = 438.83 /cm;
    # baseline 0.244 + 85.3 e^(−346/66.2) = 0.244 + 85.3 · 5.3719e-3 = 0.70222 /cm;
    # μs' = 2e12/6.25e10 + 2e5/11180.34 = 32 + 17.8885 = 49.8885 /cm. Five significant
    # figures by hand (agreement measured: 2e-5 at worst): rtol 2e-4.
    c = bp.chromophores(np.array([500.0]), formats.haemoglobin_table())
    assert c.eumelanin[0] == pytest.approx(67.916, rel=2e-4)
    assert c.pheomelanin[0] == pytest.approx(43.883, rel=2e-4)
    assert c.baseline[0] == pytest.approx(0.070222, rel=2e-4)
    assert c.scattering[0] == pytest.approx(4.98885, rel=2e-4)


def test_haemoglobin_against_an_independent_copy_of_prahls_table():
    # Prahl's e(λ) as printed in an independent public copy of the OMLC table (cm⁻¹/M):
    # 542 nm HbO2 53292, Hb 48148; 576 nm 55540, 40092; 700 nm 290, 1794.28. Whole blood
    # (150 g/L, 64500 g/mol): μa = 2.303 e · 150/64500 /cm; by hand 542 nm HbO2: 285.43 /cm.
    oxy, deoxy = bp.blood(np.array([542.0, 576.0, 700.0]), formats.haemoglobin_table())
    k = 2.303 * 150 / 64500 / 10
    assert oxy[0] == pytest.approx(28.543, rel=1e-4)
    np.testing.assert_allclose(oxy, k * np.array([53292, 55540, 290]), rtol=1e-12)
    np.testing.assert_allclose(deoxy, k * np.array([48148, 40092, 1794.28]), rtol=1e-12)
    with pytest.raises(ValueError, match="tabulated at 380-780"):
        bp.blood(np.array([379.0, 500.0]), formats.haemoglobin_table())


# --- The layers, against the textbook KM formulas written out here in numpy.

def _textbook(S, K, X, Rg):
    """Huang et al. eq. 1–2 (sinh/cosh form) and a layer over a background, float64."""
    a = 1 + K / S
    b = np.sqrt(a * a - 1)
    sh, ch = np.sinh(b * S * X), np.cosh(b * S * X)
    R0 = sh / (a * sh + b * ch)
    T = b / (a * sh + b * ch)
    return R0 + T * T * Rg / (1 - R0 * Rg)


def _r_inf(S, K):
    q = K / S
    return 1 + q - np.sqrt(q * q + 2 * q)


def _saunderson(R):
    k1 = (0.4 / 2.4) ** 2
    return (1 - k1) * 0.5 * R / (1 - 0.5 * R)


@pytest.mark.parametrize("skin", [bp.DEFAULT, bp.Skin(0.3, 0.9, 0.08, 0.2, 0.12, 0.7),
                                  bp.Skin(0.005, 0.0, 0.001, 1.0, 0.01, 6.0)])
def test_two_layers_against_the_textbook_formulas(x64, skin):
    c = chrom()
    mua_e = skin.melanin * (skin.eumelanin * c.eumelanin + (1 - skin.eumelanin) *
                            c.pheomelanin) + (1 - skin.melanin) * c.baseline
    mua_d = skin.haemoglobin * (skin.oxygenation * c.oxy + (1 - skin.oxygenation) *
                                c.deoxy) + (1 - skin.haemoglobin) * c.baseline
    S = 0.75 * skin.scattering * c.scattering
    want = _saunderson(_textbook(S, 2 * mua_e, skin.epidermis_mm, _r_inf(S, 2 * mua_d)))
    got = np.asarray(bp.reflectance(c, f64(skin)))
    np.testing.assert_allclose(got, want, rtol=1e-14)  # measured agreement 9e-16
    assert np.asarray(bp.reflectance(c, f64(skin), specular=True)) == pytest.approx(
        want + (0.4 / 2.4) ** 2, rel=1e-14)


def test_km_limits(x64):
    c = chrom()
    S_d = 0.75 * 2.5 * c.scattering
    # No epidermis: the dermis alone, R∞, through the surface.
    thin = np.asarray(bp.reflectance(c, f64(bp.DEFAULT._replace(epidermis_mm=1e-12))))
    K_d = 2 * (0.02 * (0.6 * c.oxy + 0.4 * c.deoxy) + 0.98 * c.baseline)
    # 1e-12 mm is not 0: agreement measured 1.6e-11 (the layer's own S·X ~ 1e-12).
    np.testing.assert_allclose(thin, _saunderson(_r_inf(S_d, K_d)), rtol=1e-10)
    # An opaque epidermis: its own R∞ (metres of it; no overflow).
    thick = np.asarray(bp.reflectance(c, f64(bp.DEFAULT._replace(epidermis_mm=1e3))))
    K_e = 2 * (0.06 * (0.1 * c.eumelanin + 0.9 * c.pheomelanin) + 0.94 * c.baseline)
    np.testing.assert_allclose(thick, _saunderson(_r_inf(S_d, K_e)), rtol=1e-14)  # 9e-16


def test_more_melanin_or_blood_darkens():
    c = chrom()
    m = np.asarray(bp.reflectance(c, bp.DEFAULT._replace(melanin=jnp.array([0.02, 0.1, 0.4]))))
    assert np.all(np.diff(m, axis=0) < 0)
    h = np.asarray(bp.reflectance(c, bp.DEFAULT._replace(
        haemoglobin=jnp.array([0.005, 0.02, 0.08]))))
    assert np.all(np.diff(h[:, 1:4], axis=0) < 0)  # 500, 542, 576 nm: blood absorbs
    # Oxygenation moves absorption from 650-700 nm (deoxy) to 542/576 (oxy's peaks).
    s = np.asarray(bp.reflectance(c, bp.DEFAULT._replace(oxygenation=jnp.array([0.0, 1.0]))))
    assert np.all(s[1, 4:] > s[0, 4:]) and s[1, 3] < s[0, 3]


def test_the_whole_range_renders_without_clipping():
    """Every corner of the parameter ranges (64), as linear sRGB under D65: strictly inside
    (0, 1) in every channel, no clipped or negative one (measured: 0.0064 to 0.79)."""
    grid = spectral.Grid(5)
    c = bp.chromophores(grid.wavelengths, formats.haemoglobin_table())
    corners = np.array(list(itertools.product(*(bp.RANGES[n] for n in bp.PARAMS))))
    R = np.asarray(bp.reflectance(c, bp.Skin(*corners.T.astype(np.float32))))
    rgb = R @ grid.rgb_matrix
    assert np.all(np.isfinite(rgb))
    assert rgb.min() > 0.005 and rgb.max() < 0.85
    assert np.all((R > 0) & (R < 1))


def test_maps_broadcast_per_texel():
    c = chrom()
    mel = jnp.asarray(np.linspace(0.01, 0.4, 12).reshape(3, 4), jnp.float32)
    hb = jnp.asarray(np.linspace(0.002, 0.09, 4), jnp.float32)  # broadcasts along rows
    out = np.asarray(bp.reflectance(c, bp.DEFAULT._replace(melanin=mel, haemoglobin=hb)))
    assert out.shape == (3, 4, len(WL))
    one = np.asarray(bp.reflectance(c, bp.DEFAULT._replace(melanin=mel[2, 1],
                                                           haemoglobin=hb[1])))
    np.testing.assert_allclose(out[2, 1], one, rtol=1e-6)


# --- Gradients: float64, forward and reverse, at ordinary points and the range ends.

POINTS = [bp.DEFAULT, bp.Skin(*(lo for lo, _ in bp.RANGES.values())),
          bp.Skin(*(hi for _, hi in bp.RANGES.values())),
          bp.Skin(0.5, 0.0, 0.001, 1.0, 0.15, 0.5), bp.Skin(0.005, 1.0, 0.1, 0.0, 0.01, 6.0)]


@jax.jit  # once for the module (the chromophores an argument): the points share its programs
def _reflectance(c, *values):
    return bp.reflectance(c, bp.Skin(*values))


@pytest.mark.parametrize("point", POINTS)
def test_gradients(x64, point):
    c = bp.Chromophores(*(jnp.asarray(a) for a in chrom()))

    def f(*values):
        return _reflectance(c, *values)

    scales = [0.05 * (hi - lo) for lo, hi in bp.RANGES.values()]
    check_grads_scaled(f, list(point), scales, order=1, eps=1e-4)


# --- In scenes and renders.

def test_scene_keys_and_what_is_left_out():
    nist = load_scene("makeup")
    bio = load_scene("makeup", ["material.model=biophysical"])
    also = load_scene("makeup", ["skin.model=biophysical"])
    keys = set(BIOPHYSICAL_KEYS.values())
    assert keys <= set(bio.params) and keys <= set(also.params)
    assert not keys & set(nist.params) and "skin.melanin" in nist.params
    assert "skin.melanin" not in bio.params
    assert bio.config.spectral.skin == also.config.spectral.skin == "biophysical"
    assert nist.config.spectral.skin == "nist"
    assert not keys & set(load_scene("hand").params)
    for key in keys:
        lo, hi = bp.RANGES[next(n for n, k in BIOPHYSICAL_KEYS.items() if k == key)]
        with pytest.raises(Exception, match=r"must be in \["):
            load_scene("face", ["material.model=biophysical", f"{key}={hi * 2 + 1}"])


@pytest.fixture(scope="module")
def small_face():
    over = ["material.model=biophysical", "texture.size=64", "camera.size=32",
            "camera.height=0", "sss.enabled=false", "wrinkles.enabled=false"]
    return load_scene("face", over)


def test_render_and_gradient_of_the_biophysical_face(small_face):
    sc = small_face
    arrays = render.prepare(sc.config).arrays
    assert "chromophores" in arrays and "skin" not in arrays  # no NIST spectrum read
    assert "chromophores" not in render.prepare(load_scene("face", [
        "texture.size=64", "camera.size=32", "camera.height=0", "sss.enabled=false",
        "wrinkles.enabled=false"]).config).arrays

    def mean_image(mel, hb):
        p = {**sc.params, "skin.melanin_fraction": mel, "skin.haemoglobin": hb}
        return render.render_prepared(sc.config, p, arrays, "linear_rgba")[..., :3].mean(
            axis=(0, 1))

    img = np.asarray(render.render(sc.config, sc.params, "linear_rgba"))
    assert np.all(np.isfinite(img)) and img[..., :3].max() < 1.0
    J = np.asarray(jax.jacfwd(mean_image, argnums=(0, 1))(jnp.float32(0.06),
                                                          jnp.float32(0.02)))
    assert np.all(np.isfinite(J)) and np.all(J[0] < 0)  # melanin darkens every channel
    assert J[1][1] < 0 and J[1][1] < J[1][0]  # blood takes more green than red


def test_layers_lie_on_the_biophysical_skin():
    sc = load_scene("makeup", ["skin.model=biophysical"])
    assert len(sc.config.spectral.layers) == 4 and sc.config.spectral.skin == "biophysical"
    assert math.isfinite(float(sc.params["skin.melanin_fraction"]))
