"""One radiometric scale for Blinn, Lafortune and the cosmetics model; camera exposure;
Blinn's skin colour over the whole range of melanin and blood (issue 14, items 3 and 4)."""

import colour
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import check_grads_scaled

from jaxskin import render
from jaxskin.formats import NIST_SUBJECTS as SUBJECTS
from jaxskin.formats import nist_spectrum
from jaxskin.scene import load_scene
from jaxskin.shading import blinn, lafortune

LUMA = np.array([0.2126, 0.7152, 0.0722])  # linear sRGB → Y (IEC 61966-2-1)


def decode(display):
    """sRGB display values → linear (IEC 61966-2-1), float64."""
    x = np.asarray(display, np.float64)
    return np.where(x > 0.04045, ((x + 0.055) / 1.055) ** 2.4, x / 12.92)


def unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


def test_lafortune_without_lobes_is_blinn_without_highlight(x64):
    """A Lafortune surface with no lobes and ρd = Blinn's r is Lambertian: on a flat patch
    both give I_ambient r + I_light r cos θ (by hand below), to float64 rounding."""
    m, b = np.float64(0.35), np.float64(0.6)
    r = np.asarray(blinn.skin_colour(m, b))
    zero = jnp.zeros((1, 3), jnp.float64)
    p = lafortune.Lafortune(jnp.asarray(r), zero, zero, jnp.ones((1, 3), jnp.float64))
    N, V = np.array([0.0, 0.0, 1.0]), unit([0.2, -0.1, 1.0])
    for theta in (0.0, 0.5, 1.2, 1.55):
        L = np.array([np.sin(theta), 0.0, np.cos(theta)])
        by_hand = 0.25 * r + 0.9 * r * np.cos(theta)
        c = blinn.shade(N, L, V, m, b, 0.0, 100.0, 0.25, 0.9)
        f = lafortune.shade(p, N, L, V, 0.25, 0.9)
        np.testing.assert_allclose(c, by_hand, rtol=1e-14)
        np.testing.assert_allclose(f, by_hand, rtol=1e-14)


def _hand(*overrides):
    sc = load_scene("hand", ["texture.size=128", "camera.size=96", *overrides])
    return decode(render.render(sc.config, sc.params))


def test_the_skin_preset_is_on_blinns_scale():
    """The hand with the `skin` Lafortune preset against Blinn's default skin: mean linear
    luminance over the hand. Their albedos are comparable (Y of ρd 0.33, plus the lobes'
    π f ≈ 0.07 at normal incidence, against Y of Blinn's r 0.35); measured ratio 0.94 at
    96² and 256² (0.28 before, with f not multiplied by π); band 0.8–1.25."""
    b, f = _hand(), _hand("material.model=lafortune")
    on = b.sum(-1) > 0
    ratio = (f[on] @ LUMA).mean() / (b[on] @ LUMA).mean()
    assert 0.8 < ratio < 1.25, ratio


@pytest.mark.parametrize("model", ["blinn", "lafortune"])
def test_exposure_doubles_linear_light(model):
    """camera.exposure = +1 doubles the linear image, −1 halves it (float32 rounding)."""
    base = _hand(f"material.model={model}")
    for stops in (1.0, -1.0):
        np.testing.assert_allclose(_hand(f"material.model={model}",
                                         f"camera.exposure={stops}"), 2**stops * base,
                                   rtol=2e-6, atol=1e-7)  # measured 4e-7 relative


def test_exposure_in_the_cosmetics_model():
    over = ["texture.size=64", "camera.size=32", "sss.enabled=false"]
    images = []
    for stops in (0.0, 1.0):
        sc = load_scene("face", [*over, f"camera.exposure={stops}"])
        images.append(decode(render.render(sc.config, sc.params)))
    assert images[0].max() > 0.05
    np.testing.assert_allclose(images[1], 2 * images[0], rtol=2e-6, atol=1e-7)


def test_exposure_gradient(x64):
    image = jnp.asarray([[0.1, 0.5, 0.9]], jnp.float64)
    check_grads_scaled(lambda e, x: render.expose(x, e), [0.3, image], [0.1, 0.01], order=1)


def test_cosmetics_model_on_the_same_scale(x64):
    """Bare skin of a flat (grey) spectral albedo a in the cosmetics model, no highlight, no
    blur, against a Lafortune surface with ρd = (a, a, a) and no lobes: both
    I_ambient a + I_light a cos θ (by hand), equal to float64 rounding (measured 1e-15)."""
    from jaxskin import spectral
    from jaxskin.shading import layered

    grid = spectral.Grid(step=20)
    a = 0.37
    zero = jnp.zeros((1, 3), jnp.float64)
    p = lafortune.Lafortune(jnp.full(3, a), zero, zero, jnp.ones((1, 3), jnp.float64))
    N, V = jnp.asarray([[0.0, 0.0, 1.0]]), unit([0.3, 0.1, 1.0])
    for theta in (0.0, 0.7, 1.4):
        L = jnp.asarray([np.sin(theta), 0.0, np.cos(theta)])
        skin = layered.radiance(grid, N, L, V, 0.25, 0.9, jnp.full(len(grid), a), 0.3, 0.0)
        by_hand = (0.25 + 0.9 * np.cos(theta)) * a
        np.testing.assert_allclose(skin[0], by_hand, rtol=1e-12)
        np.testing.assert_allclose(lafortune.shade(p, N, L, V, 0.25, 0.9)[0], by_hand,
                                   rtol=1e-12)


def test_the_same_light_in_every_model():
    """A white Lambertian facing the light gives I_ambient + I_light in Blinn (r = 1 is not
    a skin, so through shade's formula with the albedo factored out) and in the cosmetics
    model's irradiance."""
    from jaxskin.shading import layered

    z = jnp.asarray([0.0, 0.0, 1.0])
    assert float(layered.irradiance(z, z, 0.3, 0.7)) == pytest.approx(1.0)
    r = np.asarray(blinn.skin_colour(0.2, 0.5))
    np.testing.assert_allclose(blinn.shade(z, z, -z, 0.2, 0.5, 0.0, 100.0), r, rtol=1e-6)


# --- skin colour over melanin and blood ------------------------------------------------

GRID = np.linspace(0.0, 1.0, 11)


def _lab(linear):
    return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(linear, apply_cctf_decoding=False))


def test_skin_colour_over_the_whole_grid():
    m, b = np.meshgrid(GRID, GRID, indexing="ij")
    r = np.asarray(blinn.skin_colour(m, b), np.float64)  # (11 melanin, 11 blood, 3)
    assert r.min() > 0.01 and r.max() < 1.0  # nothing negative, nothing clipped
    # Shaded facing the light at the defaults (ambient 0.3 + light 0.7), no highlight.
    z = jnp.asarray([0.0, 0.0, 1.0])
    c = np.asarray(blinn.shade(z, z, z, m, b, 0.0, 100.0))
    assert c.min() > 0.01 and c.max() < 1.0
    Y = r @ LUMA
    assert np.all(np.diff(Y, axis=0) < 0)  # darker with melanin at every blood level
    assert np.all(np.diff(r, axis=0) < 0)  # and in every channel
    lab = _lab(r)
    hue = np.degrees(np.arctan2(lab[..., 2], lab[..., 1]))
    chroma = np.hypot(lab[..., 1], lab[..., 2])
    assert np.all((40 < hue[-1]) & (hue[-1] < 70)), hue[-1]  # brown at melanin 1
    assert np.all((10 < chroma[-1]) & (chroma[-1] < 40)), chroma[-1]  # moderate
    assert lab[-1, :, 0].max() < 40 < lab[0, :, 0].min()  # dark to light


def _cie_linear_srgb(R, wl):
    """Linear sRGB under D65 by a plain sum over the CIE 1931 tables at 5 nm (not
    colour.sd_to_XYZ's ASTM weights and not jaxskin.spectral), with the IEC 61966-2-1
    matrix typed in."""
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]
    xyz_bar = np.stack([np.interp(wl, cmfs.wavelengths, cmfs.values[:, i]) for i in range(3)], 1)
    d65 = colour.SDS_ILLUMINANTS["D65"]
    E = np.interp(wl, d65.wavelengths, d65.values)
    XYZ = (R * E) @ xyz_bar / (E @ xyz_bar[:, 1])
    M = np.array([[3.2406, -1.5372, -0.4986], [-0.9689, 1.8758, 0.0415],
                  [0.0557, -0.2040, 1.0570]])
    return XYZ @ M.T


def test_skin_colour_from_the_published_data():
    """Two grid points computed another way: the NIST spectra's mean density and melanin
    axis (numpy PCA), Jacques' darkest epidermis (6.6e11 λ^−3.33 /cm, 43 %, 60 µm, two
    passes) for the axis' length, Table 5.1's blood in density form; all integrated by a
    plain CIE sum. The paper's default (0.2, 0.5) is the NIST mean; (1, 0) the darkest.
    Agreement measured: 1.4e-4 relative (5 nm plain sums against ASTM weights)."""
    wl = np.arange(380.0, 781.0, 5.0)
    white = _cie_linear_srgb(np.ones_like(wl), wl)
    D = np.array([-np.log(_cie_linear_srgb(np.interp(wl, *nist_spectrum(s)), wl) / white)
                  for s in range(1, SUBJECTS + 1)])
    centre = D.mean(0)
    axis = np.linalg.eigh(np.cov((D - centre).T))[1][:, -1]
    axis *= np.sign(axis.sum())
    filt = np.exp(-6.6e11 * wl ** -3.33 * 0.43 * 0.006 * 2)
    a_m = axis / axis[0] * -np.log(_cie_linear_srgb(filt, wl)[0] / white[0])
    a_b = np.array([0.0, 0.24, 0.24]) / np.array([0.97, 0.87, 0.67])
    default = np.exp(-centre)
    darkest = default * np.exp(-0.8 * a_m + 0.5 * a_b)
    np.testing.assert_allclose(blinn.skin_colour(0.2, 0.5), default, rtol=1.5e-3)
    np.testing.assert_allclose(blinn.skin_colour(1.0, 0.0), darkest, rtol=1.5e-3)


@pytest.mark.parametrize("point", [(0.0, 0.0), (1.0, 1.0), (0.0, 1.0), (1.0, 0.0)])
def test_skin_colour_gradients_at_the_ends(x64, point):
    N, L, V = unit([0.1, 0.2, 0.97]), unit([0.5, -0.3, 0.8]), np.array([0.0, 0.0, 1.0])
    check_grads_scaled(blinn.skin_colour, list(point), [0.01, 0.01], order=1)
    check_grads_scaled(lambda m, b: blinn.shade(N, L, V, m, b, 0.2, 100.0), list(point),
                       [0.01, 0.01], order=1)


def test_skin_grid_renders_darker_with_melanin():
    """The README's grid (jaxskin.skin_grid): one render per (blood, melanin), darker to the
    right in every row."""
    from jaxskin.skin_grid import skin_grid

    images = decode(np.clip(skin_grid([0.0, 0.5, 1.0], [0.0, 1.0], size=24,
                                      overrides=["texture.size=64"]), 0, 1))
    assert images.shape == (2, 3, 24, 24, 3)
    on = images[0, 0].sum(-1) > 0
    Y = (images[:, :, on] @ LUMA).mean(-1)
    assert np.all(np.diff(Y, axis=1) < 0), Y
