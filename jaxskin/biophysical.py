"""A biophysical spectral skin model: melanin and haemoglobin in two Kubelka–Munk layers.

Skin as an epidermis (thickness `epidermis_mm`) lying on a dermis thick enough to be
opaque, composed with the project's own KM rule (`km.layer`, `km.over`: Kubelka's
two-layer formula, the corrected Huang et al. eq. 3), seen through the skin's surface
(Saunderson's internal reflection). λ in nm; absorption and scattering per mm.

**Absorption** (μa, per mm; the sources' cm⁻¹ divided by 10):

- eumelanin 6.6 × 10¹¹ λ^−3.33 cm⁻¹ (Jacques' melanosome, "Skin optics", OMLC News 1998;
  Donner & Jensen 2006 quote 6.6 × 10¹⁰ λ^−3.33 mm⁻¹), pheomelanin 2.9 × 10¹⁵ λ^−4.75 cm⁻¹
  (Donner & Jensen 2006, 2.9 × 10¹⁴ λ^−4.75 mm⁻¹); per unit volume fraction of melanosomes.
- oxy- and deoxy-haemoglobin: Prahl's molar extinction e(λ) (OMLC, from Gratzer and
  Kollias; `data/spectra/hemoglobin_prahl.csv`) as whole blood, 150 g/L of haemoglobin of
  64,500 g/mol: μa = 2.303 e · 150 / 64500 cm⁻¹; per unit volume fraction of blood.
- the bloodless, melanin-free tissue between them: Jacques' skin baseline
  0.244 + 85.3 exp(−(λ − 154)/66.2) cm⁻¹ (Jacques, OMLC skin optics summary, revised form;
  it replaced the 1998 power law 7.84 × 10⁸ λ^−3.255 cm⁻¹, and on the 100 NIST forearms it
  fits better: median RMS reflectance error 0.006 against 0.009).

    epidermis: μa = m (η μa,eu + (1 − η) μa,pheo) + (1 − m) μa,base
    dermis:    μa = h (s μa,HbO2 + (1 − s) μa,Hb) + (1 − h) μa,base

with m the melanosome volume fraction (`melanin`), η the eumelanin share (`eumelanin`),
h the blood volume fraction (`haemoglobin`) and s its oxygen saturation (`oxygenation`).

**Scattering**: Jacques' dermis μs' = 2 × 10¹² λ⁻⁴ + 2 × 10⁵ λ^−1.5 cm⁻¹ (Rayleigh + Mie,
"Skin optics" 1998) in both layers, times `scattering` (1: the published curve). Measured
skin is brighter than the published curve makes it: fits to the NIST forearms put
`scattering` at 1.3–4 (median 2.6); the range is open for that reason.

**From μa, μs' to KM**: K = 2 μa and S = (3/4) μs' (the diffusion-theory limit used by
Star et al. 1988 and Thennadil 2008, K = 2μa, S = (3/4)μs' − (1/4)μa, without its second
term: that term is only valid for μa ≪ μs' and makes S negative in a dark epidermis, where
melanin's μa exceeds μs' below 450 nm). K/S = (8/3) μa/μs', so R∞ follows the diffusion
picture's dependence on the albedo; any constant factor in this mapping is absorbed by
`scattering`.

**Surface**: light crosses the skin's surface (n ≈ 1.4) going in and out; the diffuse light
inside is partly reflected back (Saunderson 1942, constants.md): body reflectance
R_b = (1 − k1)(1 − k2) R / (1 − k2 R) with k1 = ((n − 1)/(n + 1))² = 0.028 (specular, at
normal incidence: it is the renderer's highlight, not part of R_b) and k2 = 0.5 (the
internal diffuse reflectance of an n = 1.4 surface, 1 − (1 − 0.07)/n² ≈ 0.53).

Every function is elementwise over broadcastable parameter arrays: scalars, or per-texel
maps `(H, W)`, give reflectance `(..., n)`. Pure JAX, jit/vmap/grad-safe; K > 0 at every
band (the baseline), so no KM limit is met at any parameter value.
"""

from __future__ import annotations

from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from . import km

__all__ = ["DEFAULT", "PARAMS", "RANGES", "Chromophores", "Skin", "baseline", "blood",
           "body_reflectance", "chromophores", "coefficients", "eumelanin", "pheomelanin",
           "reduced_scattering", "reflectance"]

BLOOD_HB_G_PER_L = 150.0  # haemoglobin in whole blood (Prahl's conversion note)
HB_G_PER_MOL = 64500.0  # its molar mass, as the table's conversion note uses
N_SKIN = 1.4
K1 = ((N_SKIN - 1) / (N_SKIN + 1)) ** 2  # 0.0278: the surface's specular reflectance
K2 = 0.5  # the internal diffuse reflectance of the surface (Saunderson's k2)

PARAMS = ("melanin", "eumelanin", "haemoglobin", "oxygenation", "epidermis_mm", "scattering")
# The literature's ranges: melanosome fraction 1.3–43 % (Jacques 1998), 0.005–0.5 in
# BioSkin's "plausible"; blood fraction 0.001–0.1 (BioSkin: regular skin to
# 0.0225); saturation 0–1 (regular 0.6–0.8); epidermis 0.01–0.15 mm (forearm ≈ 0.06–0.1);
# the scattering factor 0.5–6 (see the module docstring).
RANGES = {"melanin": (0.005, 0.5), "eumelanin": (0.0, 1.0), "haemoglobin": (0.001, 0.1),
          "oxygenation": (0.0, 1.0), "epidermis_mm": (0.01, 0.15), "scattering": (0.5, 6.0)}


class Skin(NamedTuple):
    """The model's parameters, each a scalar or an array (e.g. a per-texel map `(H, W)`);
    they broadcast together. Ranges in `RANGES`."""

    melanin: ArrayLike  # volume fraction of melanosomes in the epidermis
    eumelanin: ArrayLike  # eumelanin's share of the melanin (the rest is pheomelanin)
    haemoglobin: ArrayLike  # volume fraction of blood in the dermis
    oxygenation: ArrayLike  # oxygen saturation of that blood
    epidermis_mm: ArrayLike  # epidermis thickness
    scattering: ArrayLike  # factor on Jacques' reduced scattering


# A light-to-medium skin near the median of the fits to the 100 NIST forearms
# (benchmarks/RESULTS.md: melanin 0.071, blood 0.024, saturation 0.58, epidermis 29 µm,
# scattering 3.2), with a eumelanin share of 0.1 where those fits give ≈ 0.
DEFAULT = Skin(melanin=0.06, eumelanin=0.1, haemoglobin=0.02, oxygenation=0.6,
               epidermis_mm=0.035, scattering=2.5)


class Chromophores(NamedTuple):
    """Absorption μa of each absorber and the reduced scattering μs', per mm, `(n,)` on a
    wavelength grid (host float64; `chromophores` makes them)."""

    eumelanin: np.ndarray
    pheomelanin: np.ndarray
    oxy: np.ndarray
    deoxy: np.ndarray
    baseline: np.ndarray
    scattering: np.ndarray


def eumelanin(wl):
    """μa of eumelanin per unit volume fraction, per mm: 6.6 × 10¹⁰ λ^−3.33."""
    return 6.6e10 * np.asarray(wl, np.float64) ** -3.33


def pheomelanin(wl):
    """μa of pheomelanin per unit volume fraction, per mm: 2.9 × 10¹⁴ λ^−4.75."""
    return 2.9e14 * np.asarray(wl, np.float64) ** -4.75


def baseline(wl):
    """μa of bloodless, melanin-free skin per mm: (0.244 + 85.3 exp(−(λ − 154)/66.2)) / 10."""
    return (0.244 + 85.3 * np.exp(-(np.asarray(wl, np.float64) - 154.0) / 66.2)) / 10.0


def reduced_scattering(wl):
    """Jacques' dermis μs' per mm: (2 × 10¹² λ⁻⁴ + 2 × 10⁵ λ^−1.5) / 10."""
    wl = np.asarray(wl, np.float64)
    return (2e12 * wl ** -4.0 + 2e5 * wl ** -1.5) / 10.0


def blood(wl, table) -> tuple[np.ndarray, np.ndarray]:
    """μa per mm of whole blood, fully oxygenated and deoxygenated, at `wl` from `table =
    (wavelengths, e_HbO2, e_Hb)` (molar extinction, cm⁻¹/M; `formats.haemoglobin_table`),
    interpolated linearly; `ValueError` outside the table."""
    wl = np.asarray(wl, np.float64)
    t_wl, e_oxy, e_deoxy = (np.asarray(a, np.float64) for a in table)
    if wl.min() < t_wl[0] - 1e-9 or wl.max() > t_wl[-1] + 1e-9:
        raise ValueError(f"haemoglobin is tabulated at {t_wl[0]:g}-{t_wl[-1]:g} nm, asked "
                         f"for {wl.min():g}-{wl.max():g} nm")
    scale = 2.303 * BLOOD_HB_G_PER_L / HB_G_PER_MOL / 10.0  # cm⁻¹/M → per mm of blood
    return np.interp(wl, t_wl, e_oxy) * scale, np.interp(wl, t_wl, e_deoxy) * scale


def chromophores(wl, table) -> Chromophores:
    """Every absorber's μa and the scattering on wavelengths `wl (n,)` nm (host float64)."""
    oxy, deoxy = blood(wl, table)
    return Chromophores(eumelanin(wl), pheomelanin(wl), oxy, deoxy, baseline(wl),
                        reduced_scattering(wl))


def _band(x, dtype):
    return jnp.asarray(x, dtype)[..., None]  # a per-band axis last


def _dtype(skin: Skin):
    dtype = jnp.result_type(*(jnp.asarray(v) for v in skin), jnp.float32)
    return dtype if jnp.issubdtype(dtype, jnp.floating) else jnp.float32


def coefficients(c: Chromophores, skin: Skin) -> tuple[Float[Array, "*shape n"], ...]:
    """KM coefficients per mm: `(S_epidermis, K_epidermis, S_dermis, K_dermis)`, each
    `(*shape, n)` with `*shape` the parameters' broadcast shape. K = 2 μa, S = (3/4) μs'."""
    dtype = _dtype(skin)
    a = {k: jnp.asarray(v, dtype) for k, v in c._asdict().items()}
    m, eta = _band(skin.melanin, dtype), _band(skin.eumelanin, dtype)
    h, s = _band(skin.haemoglobin, dtype), _band(skin.oxygenation, dtype)
    mua_e = m * (eta * a["eumelanin"] + (1.0 - eta) * a["pheomelanin"]) + (1.0 - m) * a[
        "baseline"]
    mua_d = h * (s * a["oxy"] + (1.0 - s) * a["deoxy"]) + (1.0 - h) * a["baseline"]
    S = 0.75 * _band(skin.scattering, dtype) * a["scattering"]
    return S, 2.0 * mua_e, S, 2.0 * mua_d


def body_reflectance(R):
    """Saunderson's body reflectance: a KM reflectance `R` seen through the skin's surface,
    (1 − k1)(1 − k2) R / (1 − k2 R) (the specular k1 itself left out)."""
    return (1.0 - K1) * (1.0 - K2) * R / (1.0 - K2 * R)


def reflectance(c: Chromophores, skin: Skin, specular: bool = False
                ) -> Float[Array, "*shape n"]:
    """Diffuse reflectance of the skin, `(*shape, n)`: the epidermis (a KM layer) over the
    opaque dermis (R∞), through the surface (`body_reflectance`). `specular=True` adds the
    surface's own reflection k1 (an instrument that includes the specular component; the
    renderer draws it as its highlight instead).

    **Arguments:**

    - `c`: the `Chromophores` on the grid of the result.
    - `skin`: a `Skin`; each field a scalar or an array, broadcast together.
    """
    S_e, K_e, S_d, K_d = coefficients(c, skin)
    R_e, T_e = km.layer(S_e, K_e, _band(skin.epidermis_mm, S_e.dtype))
    R = body_reflectance(km.over(R_e, T_e, km.r_inf(S_d, K_d)))
    return R + K1 if specular else R
