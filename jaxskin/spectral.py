"""Wavelength grids and spectrum → CIE XYZ → linear sRGB as one matrix product.

A `Grid` names a uniform wavelength sampling and the light it is seen under. Its matrices
are computed once (on the host, in float64, by colour-science) and are constants inside
jit, so converting a spectral image is `spectra @ grid.rgb_matrix`, one matmul.

The XYZ weights are exactly colour-science's ASTM E308 tristimulus weighting for that grid
(`colour.sd_to_XYZ` is linear in the reflectance, so its weights are its values on unit
spectra), scaled so that a perfect reflector has Y = 1. RGB is linear sRGB (D65 white); a
non-D65 illuminant is first adapted to D65 with CAT02, and a perfect white is exactly white.
"""

from __future__ import annotations

import dataclasses
import functools
import warnings

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .precision import matmul

__all__ = ["ILLUMINANTS", "STEPS", "Grid", "resample", "to_rgb", "to_xyz"]

STEPS = (1, 5, 10, 20)
ILLUMINANTS = ("D65", "D55", "D50", "A")
_OBSERVER = "CIE 1931 2 Degree Standard Observer"


@dataclasses.dataclass(frozen=True)
class Grid:
    """A uniform wavelength grid and an illuminant; hashable, so it can be a static jit argument.

    **Arguments:**

    - `step`: nm between samples, one of 1, 5 (default), 10, 20 (the ASTM E308 intervals).
    - `start`, `stop`: first and last wavelength in nm (default 380–780, both included).
    - `illuminant`: `"D65"` (default), `"D55"` (Huang et al.'s measurement light), `"D50"`, `"A"`.
    """

    step: int = 5
    start: int = 380
    stop: int = 780
    illuminant: str = "D65"

    def __post_init__(self):
        for name in ("step", "start", "stop"):  # 5.0 for 5: whole numbers as ints (they
            value = getattr(self, name)          # index arrays and key caches)
            number = not isinstance(value, bool) and isinstance(
                value, (int, float, np.integer, np.floating))
            if not number or not np.isfinite(value) or value != int(value):
                raise ValueError(f"spectral grid {name} must be a whole number of nm, got "
                                 f"{value!r}")
            object.__setattr__(self, name, int(value))
        if self.step not in STEPS:
            raise ValueError(f"spectral step must be one of {STEPS} nm, got {self.step}")
        if self.illuminant not in ILLUMINANTS:
            raise ValueError(f"illuminant must be one of {ILLUMINANTS}, got {self.illuminant!r}")
        if not (360 <= self.start < self.stop <= 830) or (self.stop - self.start) % self.step:
            raise ValueError(
                f"grid {self.start}–{self.stop} nm must lie in 360–830 nm and be a whole "
                f"number of {self.step} nm steps"
            )

    @property
    def wavelengths(self) -> np.ndarray:
        """The sample wavelengths in nm, float64, shape `(n,)`."""
        return np.arange(self.start, self.stop + self.step / 2, self.step, dtype=np.float64)

    def __len__(self) -> int:
        return (self.stop - self.start) // self.step + 1

    @property
    def xyz_matrix(self) -> np.ndarray:
        """Weights `(n, 3)`: XYZ = reflectance @ W, with Y = 1 for a perfect reflector."""
        return _xyz_matrix(self.start, self.stop, self.step, self.illuminant)

    @property
    def rgb_matrix(self) -> np.ndarray:
        """Weights `(n, 3)`: linear sRGB = reflectance @ M (white under the illuminant → 1)."""
        return _rgb_matrix(self.start, self.stop, self.step, self.illuminant)

    @property
    def xyz_to_rgb(self) -> np.ndarray:
        """`(3, 3)`: linear sRGB = XYZ @ A, so that `rgb_matrix = xyz_matrix @ A`."""
        return _xyz_to_rgb(self.start, self.stop, self.step, self.illuminant)


@functools.cache
def _xyz_matrix(start: int, stop: int, step: int, illuminant: str) -> np.ndarray:
    import colour  # imported lazily: it takes a second and only grids need it

    shape = colour.SpectralShape(start, stop, step)
    n = len(shape.wavelengths)
    basis = colour.MultiSpectralDistributions(np.eye(n), shape.wavelengths)
    cmfs = colour.MSDS_CMFS[_OBSERVER]
    with warnings.catch_warnings():  # colour announces the (expected) shape alignments
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        W = colour.msds_to_XYZ(basis, cmfs, colour.SDS_ILLUMINANTS[illuminant],
                               method="ASTM E308")
    W = np.asarray(W, dtype=np.float64) / 100.0
    W.setflags(write=False)
    return W


@functools.cache
def _xyz_to_rgb(start: int, stop: int, step: int, illuminant: str) -> np.ndarray:
    import colour

    white = _xyz_matrix(start, stop, step, illuminant).sum(axis=0)  # a perfect reflector
    srgb = colour.RGB_COLOURSPACES["sRGB"]
    d65 = colour.xy_to_XYZ(srgb.whitepoint)
    adapt = colour.adaptation.matrix_chromatic_adaptation_VonKries(white, d65, transform="CAT02")
    A = adapt.T @ np.asarray(srgb.matrix_XYZ_to_RGB).T
    # sRGB's published matrix is rounded, and its white point is the CIE xy of D65, not the
    # tabulated spectrum's: white would come out 1.6e-4 off. Scale each channel so that a
    # perfect reflector is exactly (1, 1, 1): a white highlight stays white.
    A = A / (white @ A)
    A.setflags(write=False)
    return A


@functools.cache
def _rgb_matrix(start: int, stop: int, step: int, illuminant: str) -> np.ndarray:
    M = _xyz_matrix(start, stop, step, illuminant) @ _xyz_to_rgb(start, stop, step, illuminant)
    M.setflags(write=False)
    return M


def to_xyz(spectra: Float[ArrayLike, "*shape n"], grid: Grid) -> Float[Array, "*shape 3"]:
    """CIE XYZ (Y = 1 for a perfect reflector) of reflectance spectra sampled on `grid`."""
    spectra = jnp.asarray(spectra)
    _check_bands(spectra, grid)
    return matmul(spectra, jnp.asarray(grid.xyz_matrix, dtype=_float(spectra)))


def to_rgb(spectra: Float[ArrayLike, "*shape n"], grid: Grid) -> Float[Array, "*shape 3"]:
    """Linear sRGB of reflectance spectra sampled on `grid` (last axis = wavelength)."""
    spectra = jnp.asarray(spectra)
    _check_bands(spectra, grid)
    return matmul(spectra, jnp.asarray(grid.rgb_matrix, dtype=_float(spectra)))


def resample(values: ArrayLike, wavelengths: ArrayLike, grid: Grid) -> np.ndarray:
    """Linear interpolation of host-side spectra `(..., m)` from `wavelengths` onto `grid`.

    Values outside the measured range are held at the end values (and should be avoided).
    `wavelengths` may increase or decrease (read in increasing order); other orders, a
    length other than `values`' last axis, or non-finite wavelengths are a ValueError.
    """
    values = np.asarray(values, dtype=np.float64)
    wl = np.asarray(wavelengths, dtype=np.float64)
    if wl.ndim != 1 or values.ndim < 1 or len(wl) != values.shape[-1] or len(wl) < 1:
        raise ValueError(f"resample: {wl.shape} wavelengths for values of shape "
                         f"{values.shape}: one wavelength per entry of the last axis")
    if len(wl) > 1 and np.all(np.diff(wl) < 0):  # long wavelengths first: np.interp wants
        wl, values = wl[::-1], values[..., ::-1]  # increasing ones (silently wrong otherwise)
    if not np.all(np.isfinite(wl)) or np.any(np.diff(wl) <= 0):
        raise ValueError("resample: wavelengths must be finite and strictly increasing (or "
                         "all decreasing)")
    flat = values.reshape(-1, values.shape[-1])
    out = np.stack([np.interp(grid.wavelengths, wl, row) for row in flat])
    return out.reshape(*values.shape[:-1], len(grid))


def _check_bands(spectra, grid) -> None:
    if spectra.ndim < 1 or spectra.shape[-1] != len(grid):
        raise ValueError(f"spectra of shape {spectra.shape} on a grid of {len(grid)} bands "
                         f"({grid.start:g}-{grid.stop:g} nm every {grid.step:g}): the last "
                         "axis must be the grid's wavelengths")


def _float(x) -> jnp.dtype:
    return x.dtype if jnp.issubdtype(x.dtype, jnp.floating) else jnp.float32
