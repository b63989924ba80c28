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
exactly. It is differentiable, and a scene parameter (`skin.melanin`).
"""

from __future__ import annotations

import functools

import jax.numpy as jnp
import numpy as np

from .io import InputError, data_dir
from .spectral import Grid

__all__ = ["NIST_FILE", "SUBJECTS", "nist_reflectance", "nist_spectrum", "reflectance"]

NIST_FILE = "nist_skin_reflectance_M38597.csv"
SUBJECTS = 100
MELANIN_EXPONENT = -3.33
MELANIN_REFERENCE_NM = 500.0


@functools.cache
def _nist_table() -> tuple[np.ndarray, np.ndarray]:
    """Wavelengths (m,) and the subjects' mean reflectances (100, m)."""
    path = data_dir() / "spectra" / NIST_FILE
    wl, means = [], []
    for line in path.read_text(encoding="latin-1").splitlines():
        cells = line.split(",")
        if cells and cells[0].strip().isdigit():
            wl.append(float(cells[0]))
            means.append([float(cells[1 + 4 * s + 3]) for s in range(SUBJECTS)])
    return np.asarray(wl), np.asarray(means).T


def nist_spectrum(subject: int) -> tuple[np.ndarray, np.ndarray]:
    """Subject `subject` (1–100)'s mean reflectance as measured: `(wavelengths nm, R)`."""
    if not 1 <= subject <= SUBJECTS:
        raise InputError(f"NIST skin subject must be 1–{SUBJECTS}, got {subject}",
                         key="skin.subject")
    wl, means = _nist_table()
    return wl, means[subject - 1]


def nist_reflectance(subject: int, grid: Grid) -> np.ndarray:
    """Subject `subject` (1–100)'s mean reflectance on `grid` (host array, float64)."""
    return np.interp(grid.wavelengths, *nist_spectrum(subject))


def reflectance(base, melanin, grid: Grid):
    """`base (n,)` darkened by `melanin` (added optical depth at 500 nm, both passes)."""
    base = jnp.asarray(base)
    shape = (grid.wavelengths / MELANIN_REFERENCE_NM) ** MELANIN_EXPONENT
    return base * jnp.exp(-melanin * jnp.asarray(shape, base.dtype))
