"""Building blocks of the cosmetics renderer (issue 6): the skin profile blur, the Kelemen
specular, materials, thickness maps, layer stacks."""

import json
import os

import imageio.v3 as iio
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin import cosmetics, km, maps, spectral, sss
from jaxskin.io import InputError
from jaxskin.shading import kelemen

# ------------------------------------------------------------------ the skin profile


METHODS = ["fft", "separable"]


@pytest.mark.parametrize("method", METHODS)
def test_profile_weights_conserve_energy(method):
    np.testing.assert_allclose(np.sum(sss.WEIGHTS_RGB, axis=0), 1.0, atol=1e-12)
    const = np.ones((48, 64, 3))
    mask = np.zeros((48, 64), bool)
    mask[8:40, 5:60] = True
    out = np.asarray(sss.blur(const, 0.25, mask, method=method))
    # No darkening at the mesh's edge: measured 0 (float32), allowed 10 ulp.
    np.testing.assert_allclose(out[mask], 1.0, atol=1e-6)
    assert np.all(out[~mask] == 0)


def _direct_blur(E, texel, pixels):
    """An independent reference at `pixels (k, 2)`: a direct sum over the kernel window
    (not an FFT), with the profile built here from the published constants
    (test_references.py), each Gaussian sampled on the texel grid to 4σ of the widest and
    normalised there, as sss.py documents. **Returns:** `(k, 3)`, and the kernel radius."""
    from test_references import VARIANCES, WEIGHTS

    r = int(np.ceil(4 * np.sqrt(VARIANCES[-1]) / texel))
    y, x = np.mgrid[-r:r + 1, -r:r + 1] * texel
    g = np.exp(-(x * x + y * y)[..., None] / (2 * VARIANCES))
    kernel = (g / g.sum(axis=(0, 1))) @ WEIGHTS.T  # (2r + 1, 2r + 1, 3), symmetric
    return np.array([(E[i - r:i + r + 1, j - r:j + r + 1] * kernel).sum(axis=(0, 1))
                     for i, j in pixels]), r


@pytest.mark.parametrize("method, tolerance", [("fft", 6e-6), ("separable", 7e-4)])
def test_blur_matches_a_direct_sum(method, tolerance):
    """At 40 texels away from the border (where `blur` renormalises by the blurred mask).
    FFT: float32 rounding only (measured 5.2e-7). Separable: the 3σ cut (measured 6.8e-5)."""
    rng = np.random.default_rng(0)
    n = 128
    E = rng.uniform(0, 1, (n, n, 3))
    for texel in (0.3, 0.6):
        a = np.asarray(sss.blur(jnp.asarray(E, jnp.float32), texel, method=method))
        r = int(np.ceil(4 * np.sqrt(7.41) / texel))
        pixels = rng.integers(r, n - r, (40, 2))
        b, _ = _direct_blur(E, texel, pixels)
        err = np.abs(a[pixels[:, 0], pixels[:, 1]] - b).max()
        assert err < tolerance, (method, texel, err)


def test_a_kernel_wider_than_the_image_is_cut_without_changing_the_blur(x64):
    """Texels of 0.1 mm: the profile's 4σ window is 109 texels each side, the image 20 x 24.
    `profile_kernels` cuts the kernel to what the image reaches (19 and 23 texels); the blur
    equals the direct sum over the whole window (zeros around the image), renormalised by
    the blurred all-ones mask, at every texel."""
    rng = np.random.default_rng(3)
    E = rng.uniform(0, 1, (20, 24, 3))
    texel = 0.1
    assert sss.profile_kernels(texel, E.shape[:2]).shape == (3, 39, 47)
    got = np.asarray(sss.blur(jnp.asarray(E), texel))
    r = int(np.ceil(4 * np.sqrt(7.41) / texel))
    pixels = np.stack(np.mgrid[0:20, 0:24], -1).reshape(-1, 2) + r
    num, _ = _direct_blur(np.pad(E, ((r, r), (r, r), (0, 0))), texel, pixels)
    den, _ = _direct_blur(np.pad(np.ones_like(E), ((r, r), (r, r), (0, 0))), texel, pixels)
    np.testing.assert_allclose(got.reshape(-1, 3), num / den, rtol=1e-10, atol=0)


@pytest.mark.parametrize("texel", [1e-6, 1e-4, 0.2])
def test_texels_far_below_the_profile_blur_to_the_mean_not_to_black(texel):
    """A mesh a million times too small (`mesh.unit_mm = 1e-6`, in range) must not render
    black, nor `sss.texel_mm = 1e-6` dark blue: the kernel's mass within the image is
    ~1e-8, under an absolute 1e-6 threshold for "off the mesh". A uniform field
    stays uniform under a mask, and with texels far below the profile's 0.08–2.7 mm every
    texel gets the masked mean (the profile is flat over the image); the 4σ window (11
    million samples at 1e-6 mm) is not built."""
    rng = np.random.default_rng(4)
    mask = np.zeros((48, 40), np.float32)
    mask[5:40, 8:33] = 1.0
    flat = np.broadcast_to(np.float32([0.5, 0.3, 0.2]), (48, 40, 3))
    got = np.asarray(sss.blur(jnp.asarray(flat), texel, mask=jnp.asarray(mask)))
    on = mask > 0
    np.testing.assert_allclose(got[on], flat[on], rtol=2e-6)  # measured 4e-7
    assert np.all(got[~on] == 0)
    if texel < 1e-3:
        E = rng.uniform(0, 1, (48, 40, 3)).astype(np.float32)
        got = np.asarray(sss.blur(jnp.asarray(E), texel, mask=jnp.asarray(mask)))
        mean = E[on].mean(axis=0)
        np.testing.assert_allclose(got[on], np.broadcast_to(mean, got[on].shape), rtol=1e-4)


def test_energy_near_an_open_edge_is_as_documented(x64):
    """The normalised convolution keeps a uniform field uniform but does not conserve
    energy within a few mm of the mesh's edge (sss.py and docs/explanations/sss.md give
    these figures; another image gives 0.81–1.04): a unit impulse in red at
    0.1 mm texels beside a straight edge keeps 0.81 at the edge, 0.94 two texels in, 1.015
    at 27 texels; 6 mm from it (and 8 from the image's other edges), 1.0085."""
    H, W = 160, 200
    mask = np.zeros((H, W))
    mask[:, 100:] = 1.0  # the mesh: the right half
    kept = {}
    for d in (0, 2, 27, 60):
        E = np.zeros((H, W, 3))
        E[80, 100 + d] = 1.0
        out = np.asarray(sss.blur(jnp.asarray(E), 0.1, mask=jnp.asarray(mask)))
        kept[d] = out[..., 0].sum()
    assert kept[0] == pytest.approx(0.8060, abs=1e-4)
    assert kept[2] == pytest.approx(0.9415, abs=1e-4)
    assert kept[27] == pytest.approx(1.0149, abs=1e-4)
    assert kept[60] == pytest.approx(1.0085, abs=1e-4)


@pytest.mark.parametrize("method", METHODS)
def test_a_point_of_light_spreads_to_the_profile(x64, method):
    E = np.zeros((81, 81, 3))
    E[40, 40] = 1.0
    out = np.asarray(sss.blur(jnp.asarray(E), 0.5, method=method))
    np.testing.assert_allclose(out.sum(axis=(0, 1)), 1.0, atol=1e-9)
    assert out[40, 40, 2] > out[40, 40, 1] > out[40, 40, 0]  # red scatters furthest


@pytest.mark.parametrize("method", METHODS)
def test_blur_gradients(x64, method):
    rng = np.random.default_rng(1)
    E = rng.uniform(0, 1, (12, 14, 3))
    mask = np.ones((12, 14), bool)
    mask[:2] = False
    check_grads_scaled(jax.jit(lambda e: sss.blur(e, 0.4, mask, method=method)), [E], [1.0],
                       order=2)  # jitted: one program each way, not op by op

# ------------------------------------------------------------------ Kelemen


def test_kelemen_at_normal_incidence_by_hand(x64):
    """L = V = N: tan α = 0, P_H = 1/m², F = F0, |L + V|² = 4. (Off-normal, where Fresnel and
    cos⁴α matter: test_references.py. Reciprocity is not tested: the formula is symmetric in
    L and V by construction.)"""
    z = jnp.array([0.0, 0.0, 1.0])
    np.testing.assert_allclose(kelemen.specular(z, z, z, 0.3, 0.18), 0.18 / 0.09 * 0.028 / 4,
                               rtol=1e-15)  # measured 0


# Jitted once for the module (V an argument): check_grads' programs compile once for the
# four cases, not op by op.
_kelemen = jax.jit(lambda n, l_, v, r: kelemen.specular(n, l_, v, r, 0.18))


@pytest.mark.parametrize("case", ["ordinary", "grazing half vector", "rough", "smooth"])
def test_kelemen_gradients(x64, case):
    N = np.array([0.1, 0.0, 1.0]) / np.hypot(0.1, 1.0)
    L = {"ordinary": [0.4, 0.1, 0.9], "grazing half vector": [1.0, 0.0, 2e-3],
         "rough": [0.4, 0.1, 0.9], "smooth": [0.05, 0.0, 1.0]}[case]
    L = np.array(L) / np.linalg.norm(L)
    V = np.array([-0.3, 0.0, 0.95]) / np.hypot(0.3, 0.95)
    m = {"rough": 0.8, "smooth": 0.05}.get(case, 0.3)
    check_grads_scaled(lambda n, l_, r: _kelemen(n, l_, V, r), [N, L, m],
                       [1e-3, 1e-3, 0.01], eps=1e-4)


def test_kelemen_is_zero_and_finite_where_it_should_be(x64):
    z = jnp.array([0.0, 0.0, 1.0])
    cases = [(z, -z), (jnp.array([0.0, 0.0, -1.0]), z), (jnp.array([1.0, 0, 0]),
                                                          jnp.array([-1.0, 0, 0]))]
    for L, V in cases:
        value, grad = jax.value_and_grad(lambda r, L=L, V=V: kelemen.specular(z, L, V, r, 0.18))(
            0.3)
        assert float(value) == 0.0 and np.isfinite(grad)

# ------------------------------------------------------------------ materials and maps


def test_shipped_material_on_a_grid():
    grid = spectral.Grid(step=10)
    m = cosmetics.load_material("foundation_beige", grid)
    assert m.S.shape == m.K.shape == (41,) and not m.extrapolated.any()
    doc = json.loads((cosmetics.data_dir() / "materials" / "foundation_beige.json").read_text())
    np.testing.assert_allclose(m.S[::2][:20], np.asarray(doc["S_per_mm"])[::4][:20], rtol=1e-9)


BAD_MATERIALS = [
    ({"wavelength_nm": [400, 500], "S_per_mm": [1, 2]}, "K_per_mm", "missing"),
    ({"wavelength_nm": [400, 500], "S_per_mm": [1, 2], "K_per_mm": [1, 2, 3]}, "S_per_mm",
     "lengths"),
    ({"wavelength_nm": [500, 400], "S_per_mm": [1, 2], "K_per_mm": [1, 1]}, "wavelength_nm",
     "increase"),
    ({"wavelength_nm": [400, 500], "S_per_mm": [1, 0], "K_per_mm": [1, 1]}, "S_per_mm", "> 0"),
    ({"wavelength_nm": [400, 700], "S_per_mm": [1, 2], "K_per_mm": [1, 1]}, "wavelength_nm",
     "covers 400-700 nm, not all of the render grid 380-780 nm"),
    ({"wavelength_nm": [380, 780], "S_per_mm": [1, 2], "K_per_mm": [1, 1],
      "extrapolate": "spline"}, "extrapolate", "\"hold\" or \"linear\""),
]


@pytest.mark.parametrize("doc, key, words", BAD_MATERIALS)
def test_bad_materials_name_the_key(tmp_path, doc, key, words):
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(InputError) as info:
        cosmetics.load_material(path, spectral.Grid(step=20))
    assert str(info.value).startswith(f"{path}: key '{key}'") and words in str(info.value)


def test_nan_in_a_material_file_is_refused(tmp_path):
    path = tmp_path / "m.json"
    path.write_text('{"wavelength_nm": [380, 780], "S_per_mm": [NaN, 1], "K_per_mm": [1, 1]}')
    with pytest.raises(InputError, match="NaN is not a JSON number"):
        cosmetics.load_material(path, spectral.Grid(step=20))


@pytest.mark.parametrize("how", ["hold", "linear"])
def test_extrapolation_only_when_the_file_says_how(tmp_path, how):
    """log S linear in λ over 400–700 nm: "linear" continues it exactly to 380 and 780 nm
    (the analytic line), "hold" keeps the end values; the extended bands are marked."""
    wl = np.arange(400.0, 701.0, 5.0)
    S, K = np.exp(0.004 * (wl - 500)), np.exp(-0.002 * (wl - 500))
    doc = {"wavelength_nm": wl.tolist(), "S_per_mm": S.tolist(), "K_per_mm": K.tolist(),
           "extrapolate": how}
    path = tmp_path / "m.json"
    path.write_text(json.dumps(doc))
    grid = spectral.Grid(step=20)
    m = cosmetics.load_material(path, grid)
    g = grid.wavelengths
    np.testing.assert_array_equal(m.extrapolated, (g < 400) | (g > 700))
    if how == "linear":
        np.testing.assert_allclose(m.S, np.exp(0.004 * (g - 500)), rtol=1e-12)
        np.testing.assert_allclose(m.K, np.exp(-0.002 * (g - 500)), rtol=1e-12)
    else:
        assert m.S[0] == pytest.approx(S[0]) and m.S[-1] == pytest.approx(S[-1])


def test_region_and_image_maps(tmp_path):
    e = cosmetics.ellipse_map(400, 400, (0.5, 0.5), (0.2, 0.1), 0.02, angle_deg=30)
    assert abs((e > 0).mean() - np.pi * 0.2 * 0.1) < 0.002 and e.max() == 0.02
    p = cosmetics.polygon_map(100, 100, [(0.2, 0.2), (0.6, 0.2), (0.6, 0.7), (0.2, 0.7)],
                              0.03, feather=0.02)
    assert abs((p >= 0.015).mean() - 0.2) < 0.01 and p.max() == 0.03 and p.min() == 0.0
    assert 0 < np.mean((p > 0) & (p < 0.03)) < 0.1  # a soft edge
    img = np.array([[255, 0], [0, 128]], np.uint8)
    iio.imwrite(tmp_path / "map.png", img)
    m = cosmetics.image_map(maps.read_grey(tmp_path / "map.png"), 4, 4, 0.05)
    np.testing.assert_allclose(m[:2, :2], 0.05)
    np.testing.assert_allclose(m[2:, 2:], 0.05 * 128 / 255)
    np.testing.assert_allclose(m[:2, 2:], 0.0)

def test_a_grey_and_alpha_map_reads_its_grey_not_its_alpha(tmp_path):
    """A layer map saved as grey + alpha (2 channels): the thickness is the grey. (The
    cosmetics module's own reader once averaged the alpha in: 0 grey, opaque, read 0.5.)"""
    la = np.zeros((2, 2, 2), np.uint8)
    la[..., 0] = [[0, 100], [200, 255]]
    la[..., 1] = 255
    (tmp_path / "la.png").write_bytes(maps.png_bytes(la))
    assert iio.imread(tmp_path / "la.png").shape == (2, 2, 2)  # saved as grey + alpha
    np.testing.assert_array_equal(maps.read_grey(tmp_path / "la.png"), la[..., 0] / 255)
    m = cosmetics.image_map(maps.read_grey(tmp_path / "la.png"), 4, 4, 1.0)
    assert m[0, 0] == 0.0 and m[3, 3] == 1.0 and m[0, 3] == 100 / 255


def test_the_optics_modules_read_no_files():
    """Optics and geometry are pure functions of arrays: images are read at the edge
    (`maps.read_grey`), never inside them."""
    import inspect

    from jaxskin import biophysical, bump, km, spectral, sss, wrinkles

    for module in (cosmetics, km, spectral, sss, biophysical, bump, wrinkles):
        source = inspect.getsource(module)
        assert "imageio" not in source and "imread" not in source, module.__name__
    with pytest.raises(ValueError, match="pass its array"):
        spec = type("Spec", (), {"name": "blush", "image": "map.png"})()
        cosmetics.coverage(spec, np.zeros((0, 2)), 4, 4)


# ------------------------------------------------------------------ layering



def test_zero_thickness_is_exactly_no_makeup_and_energy_holds(three_materials):
    _, S, K = three_materials
    slab = cosmetics.layers(S, K, np.zeros((3, 4, 5)))
    assert np.all(np.asarray(slab.R) == 0) and np.all(np.asarray(slab.T) == 1)
    X = np.random.default_rng(0).uniform(0, 0.5, (3, 4, 5))
    slab = cosmetics.layers(S, K, X)
    assert np.all(np.asarray(slab.R + slab.T) <= 1 + 1e-6)


def test_thicker_layers_move_the_colour_toward_the_cosmetics_own(three_materials):
    """Per band, |R(X) − R∞| falls monotonically with thickness (KM over any background).
    In colour, bands that approach R∞ from above and from below mix (and sRGB weighs some
    negatively), so the distance falls strictly until it is within 0.005 and never rises
    above that (measured: 0.45, 0.020, 0.0016, then a wobble below 0.004)."""
    grid, S, K = three_materials
    skin = np.linspace(0.3, 0.6, len(grid))
    r_inf = np.asarray(km.r_inf(S[2], K[2]))
    target = np.asarray(spectral.to_rgb(r_inf, grid))
    gaps, distances = [], []
    for x in np.linspace(0, 0.6, 13):
        slab = cosmetics.layers(S[2:], K[2:], np.full((1, 1, 1), x))
        R = np.asarray(km.over(slab.R, slab.T, skin, slab.R_back))[0, 0]
        gaps.append(np.abs(R - r_inf))
        distances.append(np.linalg.norm(np.asarray(spectral.to_rgb(R, grid)) - target))
    assert np.all(np.diff(np.array(gaps), axis=0) <= 1e-7)
    d = np.array(distances)
    close = np.argmax(d < 0.005)
    assert close > 0 and np.all(np.diff(d[:close + 1]) < 0) and np.all(d[close:] < 0.005), d


def test_layer_gradients_wrt_thickness_and_materials(x64, three_materials):
    _, S, K = three_materials
    X = np.random.default_rng(2).uniform(0.0, 0.2, (3, 2, 3))
    X[0, 0, 0] = 0.0  # an edge of a cosmetic map
    check_grads_scaled(jax.jit(lambda s, k, x: cosmetics.layers(s, k, x).R), [S, K, X],
                       [S, K, 0.05], order=1)


def test_a_precomputed_mask_norm_gives_the_same_blur():
    rng = np.random.default_rng(5)
    E = jnp.asarray(rng.uniform(0, 1, (40, 30, 3)), jnp.float32)
    mask = jnp.asarray(rng.uniform(size=(40, 30)) > 0.3)
    norm = sss.mask_norm(mask.astype(jnp.float32), 0.3)
    assert norm.shape == (3, 40, 30)
    np.testing.assert_array_equal(sss.blur(E, 0.3, mask, norm=norm), sss.blur(E, 0.3, mask))


def test_a_material_name_is_a_shipped_one_only_when_it_is_a_bare_name(tmp_path):
    """`material_path`: a bare name finds the shipped JSON; a name with folders in it is a
    path from `base`, never a lookup under data/materials (where `../..` climbed out and
    told whether some `.json` elsewhere existed)."""
    from jaxskin.cosmetics import material_path
    from jaxskin.io import data_dir

    assert material_path("blush_rose") == data_dir() / "materials" / "blush_rose.json"
    assert material_path("x/../blush_rose", tmp_path) == (tmp_path / "blush_rose").resolve()
    leak = tmp_path / "leak.json"
    leak.write_text("{}")
    climb = os.path.relpath(tmp_path / "leak", data_dir() / "materials")
    assert material_path(climb, tmp_path) == (tmp_path / climb).resolve() != leak


def test_a_colour_thickness_map_is_read_as_its_mean_with_one_warning(tmp_path):
    """A pure red PNG as a layer's `image` renders at a third of the thickness: it is read
    as the mean of R, G, B (as documented), and said once per file; a grey image is read
    without a word."""
    import warnings

    import imageio.v3 as iio

    from jaxskin import maps

    red = np.zeros((5, 7, 3), np.uint8)
    red[..., 0] = 255
    iio.imwrite(tmp_path / "red.png", red)
    iio.imwrite(tmp_path / "grey.png", np.full((5, 7, 3), 128, np.uint8))
    with pytest.warns(UserWarning, match=r"red\.png: a colour image where a greyscale map is "
                                         r"expected: read as the mean of R, G and B \(mean "
                                         r"0\.333 of 1\)"):
        grey = maps.read_grey(tmp_path / "red.png")
    np.testing.assert_allclose(grey, 1.0 / 3.0)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        maps.read_grey(tmp_path / "red.png")  # said once
        np.testing.assert_allclose(maps.read_grey(tmp_path / "grey.png"), 128 / 255)


def test_a_map_that_is_not_square_is_warned_about_once(tmp_path):
    """A 300x200 layer map is stretched over the square texture: the checks say so, once
    a file; a square map, or one a pixel off, is read without a word."""
    import warnings

    import imageio.v3 as iio

    from jaxskin.checks import check_scene
    from jaxskin.scene import load_scene

    iio.imwrite(tmp_path / "rect.png", np.full((200, 300), 40000, np.uint16))
    iio.imwrite(tmp_path / "square.png", np.full((201, 200), 40000, np.uint16))
    for name in ("rect", "square"):
        (tmp_path / f"{name}.toml").write_text(
            '[mesh]\nfile = "face"\nprojection = "uv"\nunit_mm = 10.0\n'
            '[material]\nmodel = "spectral"\n[texture]\nsize = 64\n[camera]\nsize = 32\n'
            '[[layer]]\nname = "blush"\n'
            f'material = "blush_rose"\nthickness_mm = 0.03\nimage = "{name}.png"\n')
    rect = load_scene(str(tmp_path / "rect.toml"))
    with pytest.warns(UserWarning, match=r"layer\.blush\.image = .*rect\.png: 300x200 pixels, "
                                         r"stretched over the square texture"):
        check_scene(rect, 1)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        check_scene(rect, 1)  # said once
        check_scene(load_scene(str(tmp_path / "square.toml")), 1)


def test_blur_names_a_wrong_shape():
    """An image without its channel axis is named, not a broadcasting TypeError."""
    with pytest.raises(ValueError, match=r"irradiance must be \(H, W, 3\)"):
        sss.blur(jnp.ones((8, 8)), 0.1)
    with pytest.raises(ValueError, match=r"mask \(4, 4\) must be the image's"):
        sss.blur(jnp.ones((8, 8, 3)), 0.1, mask=jnp.ones((4, 4)))


def test_an_image_past_pillows_pixel_limit_is_named_so(tmp_path, monkeypatch):
    """A 30000² PNG that Pillow refuses for its size is named so, not "not a file format
    imageio decodes, or a truncated or damaged one"; here the limit is lowered to 1000 pixels
    (Pillow refuses past twice it)."""
    from PIL import Image

    from jaxskin.io import InputError
    from jaxskin.maps import read_image

    path = tmp_path / "big.png"
    iio.imwrite(path, np.zeros((100, 100), np.uint8))
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 1000)
    with pytest.raises(InputError, match=r"big.png: cannot read as an image: larger than the "
                                         r"2,000 pixels an image may be"):
        read_image(path)
