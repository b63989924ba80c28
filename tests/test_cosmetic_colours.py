"""The shipped cosmetics look like their names (issue 14, item 5): each material's mass tone
against the published spectrum it was made from, the foundations' order, and the colours
on the makeup face."""

import colour
import numpy as np
import pytest

from jaxskin import cosmetics, km, render, spectral
from jaxskin.formats import nist_spectrum
from jaxskin.scene import load_scene

GRID = spectral.Grid(step=10)
D65 = colour.SDS_ILLUMINANTS["D65"]


def chart(patch):
    sd = colour.SDS_COLOURCHECKERS["BabelColor Average"][patch]
    return sd.wavelengths, sd.values


def ks(R):
    return (1 - R) ** 2 / (2 * R)


def from_ks(q):
    return 1 + q - np.sqrt(q * q + 2 * q)


def lab_of_spectrum(wl, R):
    """CIELAB (D65) of a reflectance by colour-science, on the source's own sampling."""
    sd = colour.SpectralDistribution(dict(zip(wl, R, strict=True)))
    return colour.XYZ_to_Lab(colour.sd_to_XYZ(sd, illuminant=D65) / 100)


def lab_of_linear(rgb):
    return colour.XYZ_to_Lab(colour.sRGB_to_XYZ(rgb, apply_cctf_decoding=False))


def chroma_hue(lab):
    return np.hypot(lab[1], lab[2]), np.degrees(np.arctan2(lab[2], lab[1])) % 360


def _source(name):
    """The published spectrum (or its KM mixture) each product's mass tone is made from,
    written out again here (data/README.md has the table)."""
    wl, white = chart("white 9.5 (.05 D)")
    if name == "foundation_light":  # NIST's 3 nm sampling, on colour-science's 5 nm
        wl5 = np.arange(380.0, 781.0, 5.0)
        return wl5, np.interp(wl5, *nist_spectrum(42))
    if name == "foundation_beige":
        return chart("light skin")
    if name in ("foundation_dark",):
        return chart("dark skin")
    if name == "lipstick_red":
        return chart("red")
    if name == "blush_rose":
        return wl, from_ks(0.2 * ks(chart("moderate red")[1]) + 0.8 * ks(white))
    if name == "eyeshadow_taupe":
        return wl, from_ks(0.5 * ks(chart("dark skin")[1]) + 0.5 * ks(
            chart("neutral 5 (.70 D)")[1]))
    raise KeyError(name)


PRODUCTS = ("foundation_light", "foundation_beige", "foundation_dark", "blush_rose",
            "lipstick_red", "eyeshadow_taupe")


def _mass_tone(name):
    m = cosmetics.load_material(name, GRID)
    return GRID.wavelengths, np.asarray(km.r_inf(m.S, m.K), np.float64)


@pytest.mark.parametrize("name", PRODUCTS)
def test_mass_tone_is_the_published_colour(name):
    """The calibrated material's R∞ (after the synthetic measurement's noise and the fit)
    against its source, ΔE2000 under D65. Measured: 0.03–0.13; bound 1."""
    assert name in cosmetics.shipped_materials()
    got = lab_of_spectrum(*_mass_tone(name))
    want = lab_of_spectrum(*_source(name))
    assert colour.delta_E(got, want, method="CIE 2000") < 1.0


def test_foundations_light_to_dark():
    L = [lab_of_spectrum(*_mass_tone(f"foundation_{s}"))[0] for s in ("light", "beige", "dark")]
    assert L[0] > L[1] + 3 and L[1] > L[2] + 10, L
    # Also as worn: 10 µm over the makeup face's skin (NIST subject 12).
    skin = np.interp(GRID.wavelengths, *nist_spectrum(12))
    worn = []
    for s in ("light", "beige", "dark"):
        m = cosmetics.load_material(f"foundation_{s}", GRID)
        R = np.asarray(km.over(*km.layer(m.S, m.K, 0.01), skin), np.float64)
        worn.append(lab_of_spectrum(GRID.wavelengths, R)[0])
    assert worn[0] > worn[1] > worn[2], worn


def decode(display):
    x = np.asarray(display, np.float64)
    return np.where(x > 0.04045, ((x + 0.055) / 1.055) ** 2.4, x / 12.92)


@pytest.fixture(scope="module")
def makeup_renders():
    """The makeup face (128 px, SSS on), and the same with each layer at zero thickness."""
    def image(*over):
        sc = load_scene("makeup", ["camera.size=128", *over])
        return decode(render.render(sc.config, sc.params))

    full = image()
    return full, {n: image(f"layer.{n}.thickness_mm=0") for n in ("lipstick", "blush",
                                                                    "eyeshadow")}


def _region(full, without):
    """Where a layer changes the picture: over half the largest change."""
    d = np.abs(full - without).sum(-1)
    return d > 0.5 * d.max()


def test_lipstick_is_red_on_the_lips(makeup_renders):
    """Mean colour (linear) on the lips: C* > 45, hue 15–40° (red). Measured: C* 54, h 27°
    (the old synthetic lipstick: C* 35, h 14°, a dusty rose)."""
    full, without = makeup_renders
    lips = _region(full, without["lipstick"])
    assert lips.sum() > 100
    C, h = chroma_hue(lab_of_linear(full[lips].mean(0)))
    assert C > 45 and 15 < h < 40, (C, h)


def test_blush_is_pink_not_lilac(makeup_renders):
    """On the cheeks: hue 0–35° (pink; lilac is 300–340°), chroma above the bare skin's.
    Measured: C* 22, h 17° (bare: C* 14, h 56°)."""
    full, without = makeup_renders
    cheeks = _region(full, without["blush"])
    C, h = chroma_hue(lab_of_linear(full[cheeks].mean(0)))
    C0, _ = chroma_hue(lab_of_linear(without["blush"][cheeks].mean(0)))
    assert 0 < h < 35 and C > C0 + 4, (C, h, C0)


def test_eye_shadow_on_both_upper_lids(makeup_renders):
    """The eye shadow's region: two blobs, left and right of the nose, in the upper part of
    the face, darker than the bare lid (measured: L* 45 against 67)."""
    full, without = makeup_renders
    lids = _region(full, without["eyeshadow"])
    rows, cols = np.nonzero(lids)
    assert lids.sum() > 100 and rows.max() < 0.4 * lids.shape[0]
    assert np.sum(cols < 0.45 * lids.shape[1]) > 40 and np.sum(cols > 0.55 * lids.shape[1]) > 40
    L, L0 = (lab_of_linear(x[lids].mean(0))[0] for x in (full, without["eyeshadow"]))
    assert L < L0 - 10, (L, L0)
