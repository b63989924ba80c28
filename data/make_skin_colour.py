"""Derive Blinn's skin colour constants (`jaxskin.shading.blinn`) from published data.

    python data/make_skin_colour.py      # prints R_BASE, A_MELANIN, A_BLOOD

The model is r_j = r_base,j · exp(−k_melanin A_melanin,j − k_blood A_blood,j) in linear
sRGB: Bando's plane of skin colours (eq. 5.7, after Tsumura et al.) written in optical
density, −ln r, where melanin and haemoglobin add. The numbers:

- **melanin direction**: the first principal axis of the optical densities −ln(linear sRGB,
  D65) of the 100 NIST skin spectra (Cooksey et al. 2017, `spectra/`; it carries 98 % of
  their variance), the way Tsumura et al. found the melanin axis of skin colour.
- **melanin scale**: k_melanin = 1 is Jacques' darkest epidermis (43 % melanosomes, μa =
  6.6e11 λ^−3.33 /cm) in 60 µm of epidermis, passed twice: the red channel's optical
  density of that filter under D65, 1.56, fixes the length of the axis.
- **blood**: Table 5.1's a_blood in density form at the melanin-free base, a_blood / r_base
  (Bando's numbers, equal to eq. 5.7 to first order).
- **base**: placed so that the paper's default skin (k_melanin 0.2, k_blood 0.5) is the
  NIST subjects' mean density (their geometric-mean colour).
"""

from __future__ import annotations

import colour
import numpy as np

from jaxskin.formats import NIST_SUBJECTS as SUBJECTS
from jaxskin.formats import nist_spectrum

WL = np.arange(380.0, 781.0, 5.0)
TABLE_5_1 = {"r_base": (0.97, 0.87, 0.67), "a_blood": (0.00, 0.24, 0.24)}
JACQUES_DARKEST = 2 * 0.43 * 0.006  # two passes, 43 % melanosomes, 60 µm = 0.006 cm


def linear_srgb(R):
    """Linear sRGB (D65, white → 1) of a reflectance on `WL`, by colour-science."""
    sd = colour.SpectralDistribution(dict(zip(WL, R, strict=True)))
    d65 = colour.SDS_ILLUMINANTS["D65"]
    white = colour.sd_to_XYZ(colour.SpectralDistribution(dict.fromkeys(WL, 1.0)), illuminant=d65)
    return colour.XYZ_to_sRGB(colour.sd_to_XYZ(sd, illuminant=d65) / white[1],
                              apply_cctf_encoding=False)


def constants():
    D = np.array([-np.log(linear_srgb(np.interp(WL, *nist_spectrum(s))))
                  for s in range(1, SUBJECTS + 1)])
    centre = D.mean(axis=0)
    axis = np.linalg.svd(D - centre)[2][0]
    axis *= np.sign(axis.sum())
    melanosome = 6.6e11 * WL ** -3.33 * JACQUES_DARKEST
    red = -np.log(linear_srgb(np.exp(-melanosome))[0] / linear_srgb(np.ones_like(WL))[0])
    a_melanin = axis * red / axis[0]
    a_blood = np.asarray(TABLE_5_1["a_blood"]) / np.asarray(TABLE_5_1["r_base"])
    r_base = np.exp(-(centre - 0.2 * a_melanin - 0.5 * a_blood))
    return r_base, a_melanin, a_blood


if __name__ == "__main__":
    for name, v in zip(("R_BASE", "A_MELANIN", "A_BLOOD"), constants(), strict=True):
        print(f"{name} = ({', '.join(f'{c:.4f}' for c in v)})")
