"""Spectral grids: equal to colour-science, white stays white, one matmul under jit."""

import colour
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax.test_util import check_grads

from jaxskin import spectral

CMFS = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"]


@pytest.mark.parametrize("patch", ["dark skin", "light skin"])
@pytest.mark.parametrize("step", [5, 10, 20])
@pytest.mark.parametrize("illuminant", ["D65", "D55"])
def test_xyz_agrees_with_colour_sd_to_xyz(x64, patch, step, illuminant):
    grid = spectral.Grid(step=step, illuminant=illuminant)
    sd = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"][patch].copy()
    values = sd.align(colour.SpectralShape(grid.start, grid.stop, step)).values
    expected = (
        colour.sd_to_XYZ(
            colour.SpectralDistribution(values, grid.wavelengths),
            CMFS,
            colour.SDS_ILLUMINANTS[illuminant],
        )
        / 100.0
    )
    got = np.asarray(spectral.to_xyz(jnp.asarray(values), grid))
    np.testing.assert_allclose(got, expected, rtol=6e-15)  # measured 6.3e-16


@pytest.mark.parametrize("illuminant", spectral.ILLUMINANTS)
def test_perfect_white_is_rgb_white(illuminant):
    grid = spectral.Grid(step=10, illuminant=illuminant)
    rgb = spectral.to_rgb(jnp.ones(len(grid)), grid)
    assert rgb.dtype == jnp.float32
    np.testing.assert_allclose(rgb, 1.0, rtol=1e-6)  # float32: measured 3.6e-7


def test_dark_skin_srgb_matches_colour(x64):
    grid = spectral.Grid(step=5)
    sd = colour.SDS_COLOURCHECKERS["ColorChecker N Ohta"]["dark skin"]
    values = sd.copy().align(colour.SpectralShape(380, 780, 5)).values
    XYZ = colour.sd_to_XYZ(sd, CMFS, colour.SDS_ILLUMINANTS["D65"]) / 100
    expected = colour.XYZ_to_RGB(XYZ, "sRGB", apply_cctf_encoding=False)
    # Measured 1.9e-5: jaxskin scales each channel so a perfect white is exactly 1 (a change
    # below 2e-4; the exact pipeline, white scaling included: test_references.py).
    np.testing.assert_allclose(spectral.to_rgb(jnp.asarray(values), grid), expected, atol=2e-4)


def test_conversion_is_one_matmul_under_jit_and_differentiable(x64):
    grid = spectral.Grid(step=10)
    spectra = jnp.asarray(np.random.default_rng(1).uniform(0, 1, (4, 5, len(grid))))
    jaxpr = jax.make_jaxpr(lambda s: spectral.to_rgb(s, grid))(spectra)
    assert [e.primitive.name for e in jaxpr.eqns] == ["dot_general"]
    assert jax.jit(spectral.to_rgb, static_argnums=1)(spectra, grid).shape == (4, 5, 3)
    check_grads(lambda s: spectral.to_rgb(s, grid), (spectra,), order=2, modes=("fwd", "rev"))


def test_grid_validation():
    assert len(spectral.Grid()) == 81 and len(spectral.Grid(step=1)) == 401
    for bad in (dict(step=3), dict(illuminant="F2"), dict(start=300), dict(start=381)):
        with pytest.raises(ValueError):
            spectral.Grid(**bad)


def test_resample_onto_grid():
    grid = spectral.Grid(step=20)
    wl = np.arange(379.0, 782.0, 3.0)
    out = spectral.resample(2.0 * wl, wl, grid)
    np.testing.assert_allclose(out, 2.0 * grid.wavelengths)


def test_resample_reads_descending_wavelengths_and_refuses_others():
    """Wavelengths long ones first would give [1, 0, 0, …] for a ramp (np.interp wants
    them increasing): read in increasing order; a shuffled order, a length other than
    the values' and NaN are refused."""
    grid = spectral.Grid(step=10)
    np.testing.assert_allclose(spectral.resample([1.0, 0.0], [780.0, 380.0], grid),
                               (grid.wavelengths - 380.0) / 400.0, atol=1e-15)
    for values, wl in (([1.0, 0.0, 2.0], [380.0, 780.0, 500.0]), ([1.0, 0.0], [380.0]),
                       ([1.0, 0.0], [380.0, np.nan])):
        with pytest.raises(ValueError, match="resample"):
            spectral.resample(values, wl, grid)


def test_grid_takes_whole_floats_and_the_conversions_check_the_bands():
    """Grid(step=5.0) is a whole step, not a failure deep in arange; 40 bands on a 41-band
    grid is named, not a dot_general TypeError."""
    assert spectral.Grid(step=5.0) == spectral.Grid(step=5)
    assert hash(spectral.Grid(step=10.0)) == hash(spectral.Grid(step=10))
    for bad in (5.5, "5", True, float("nan")):
        with pytest.raises(ValueError, match="whole number of nm"):
            spectral.Grid(step=bad)
    for convert in (spectral.to_rgb, spectral.to_xyz):
        with pytest.raises(ValueError, match=r"spectra of shape \(40,\) on a grid of 41 bands"):
            convert(np.ones(40), spectral.Grid(step=10))
