"""Spectral skin reflectance for the cosmetics renderer: measured, with a melanin control.

The skin under the cosmetics is a measured spectrum, the NIST reference set of human skin
reflectance (Cooksey, Allen, Tsai, J. Res. NIST 122:26, 2017; 100 subjects, inner forearm,
diffuse reflectance factor), subject `subject`'s mean of three readings. We use measured
spectra rather than the melanin/blood RGB model (`shading.blinn`) because the KM layering is
spectral: an RGB skin colour has no spectrum to put under a cosmetic, and a made-up one
would put the error where the cosmetics scientist looks.

`melanin` darkens that spectrum by extra melanin in the epidermis, two passes of the
light through it (in and out), with melanin's absorption spectrum μ_a ∝ λ^−3.33 (Jacques,
"Skin optics", Oregon Medical Laser Center News 1998):

    R(λ) = R_NIST(λ) · exp(−melanin · (λ / 500 nm)^−3.33)

so `melanin` is the added optical depth (both passes) at 500 nm; 0 gives the measurement
exactly. It is differentiable, and a scene parameter (`skin.melanin`). The measured spectra
are read by `formats.nist_spectrum` / `formats.nist_reflectance`; this module is arrays only.
"""

from __future__ import annotations

import jax.numpy as jnp

from .spectral import Grid

__all__ = ["reflectance"]

MELANIN_EXPONENT = -3.33
MELANIN_REFERENCE_NM = 500.0


def reflectance(base, melanin, grid: Grid):
    """`base (n,)` darkened by `melanin` (added optical depth at 500 nm, both passes)."""
    base = jnp.asarray(base)
    shape = (grid.wavelengths / MELANIN_REFERENCE_NM) ** MELANIN_EXPONENT
    return base * jnp.exp(-melanin * jnp.asarray(shape, base.dtype))
