"""Make the example measurement CSVs in data/measurements/ (synthetic, from published colours).

We have no spectroradiometer readings of real cosmetics we may ship, so these files are
made from chosen S(λ), K(λ) with the Kubelka–Munk forward model (jaxskin.km, float64), then
given instrument-like noise (σ = 0.001 in reflectance, 4 decimals) with a fixed seed.

The colours come from published reflectance spectra. Each product's mass tone (its
reflectance when opaque, R∞) is a measured spectrum, and KM's R∞ = 1 + K/S − √((K/S)² +
2 K/S) fixes K/S = (1 − R∞)² / (2 R∞) per band; the scattering S(λ) = S₅₅₀ (550 nm / λ)
(pigment particles near the wavelength's size) sets how much a film of given thickness
hides what is under it. Spectra: the BabelColor average of 30 ColorChecker charts
(BabelColor 2012, via colour-science's `SDS_COLOURCHECKERS`, 380–730 nm, held flat to
780 nm) and the NIST skin reflectance set (Cooksey et al. 2017, `spectra/`).

Mass tones (S₅₅₀ per mm in brackets; the table in data/README.md has the sources):

- foundation_light: NIST subject 42, the set's lightest skin, L* 74 (40): a foundation
  is made to match a skin;
- foundation_beige: ColorChecker "light skin", L* 65 (40);
- foundation_dark: ColorChecker "dark skin", L* 38 (40);
- blush_rose: 20 % ColorChecker "moderate red" in the chart's "white 9.5", mixed by K/S
  (KM's one-constant rule): a red pigment tinted with white, rose pink L* 69, C* 33,
  h 12° (30);
- lipstick_red: ColorChecker "red", L* 41, C* 57, h 27° (150: opaque in one coat);
- eyeshadow_taupe: ColorChecker "dark skin" and "neutral 5" 1:1 by K/S, a taupe,
  L* 43, C* 13, h 53° (60).

The files exercise every form the reader accepts: several thicknesses over a black card, and a
bare `R` with `# thickness_mm:` over a white card as raw radiance (E_… and E_white under D55,
the paper's light; the blush). The thicknesses are chosen per product so that the films are
not opaque in most bands; the lipstick is opaque below about 600 nm even at 3 µm, where S is
not identifiable (the calibration report shades those bands).

    python data/make_measurements.py      # rewrites data/measurements/*.csv
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from jaxskin import km
from jaxskin.io import atomic_write

WL = np.arange(380.0, 781.0, 5.0)
OUT = Path(__file__).resolve().parent / "measurements"

# name: (mass tone, S at 550 nm per mm, measured thicknesses in mm over a black card)
PRODUCTS = {
    "foundation_light": ("nist:42", 40.0, (0.003, 0.01)),
    "foundation_beige": ("cc:light skin", 40.0, (0.003, 0.01)),
    "foundation_dark": ("cc:dark skin", 40.0, (0.003, 0.01)),
    "blush_rose": ("tint:moderate red:0.2", 30.0, (0.02,)),  # over white, as radiance
    "lipstick_red": ("cc:red", 150.0, (0.003, 0.01)),
    "eyeshadow_taupe": ("mix:dark skin:neutral 5 (.70 D)", 60.0, (0.003, 0.01)),
}


def k_over_s(R_inf):
    """KM: K/S of an opaque film of reflectance R∞."""
    return (1.0 - R_inf) ** 2 / (2.0 * R_inf)


def _chart(patch: str) -> np.ndarray:
    import colour

    sd = colour.SDS_COLOURCHECKERS["BabelColor Average"][patch]
    return np.interp(WL, sd.wavelengths, sd.values)  # held flat beyond 730 nm


def mass_tone(source: str) -> np.ndarray:
    """R∞ on `WL` of a `PRODUCTS` source string."""
    kind, *args = source.split(":")
    if kind == "cc":
        return _chart(args[0])
    if kind == "nist":
        from jaxskin.formats import nist_spectrum

        return np.interp(WL, *nist_spectrum(int(args[0])))
    if kind == "tint":  # share c of a chart colour in the chart's white, by K/S
        c = float(args[1])
        q = c * k_over_s(_chart(args[0])) + (1 - c) * k_over_s(_chart("white 9.5 (.05 D)"))
    elif kind == "mix":  # two chart colours 1:1 by K/S
        q = 0.5 * (k_over_s(_chart(args[0])) + k_over_s(_chart(args[1])))
    else:
        raise KeyError(source)
    return 1.0 + q - np.sqrt(q * q + 2.0 * q)


def true_spectra(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The chosen S(λ), K(λ) per mm behind each example (also used by the tests)."""
    source, S550, _ = PRODUCTS[name]
    S = S550 * (550.0 / WL)
    return S, S * k_over_s(mass_tone(source))


def simulate(S, K, thicknesses, Rg):
    """Noise-free R over `Rg` for each thickness, and R∞ (float64)."""
    with jax.enable_x64(True):
        R = [np.asarray(km.over(*km.layer(S, K, X), Rg)) for X in thicknesses]
        return np.array(R), np.asarray(km.r_inf(S, K))


def _write(path, comments, header, columns):
    with atomic_write(path, "w") as fh:
        for c in comments:
            fh.write(f"# {c}\n")
        fh.write(",".join(header) + "\n")
        for row in zip(*columns, strict=True):
            fh.write(",".join(f"{v:.0f}" if i == 0 else f"{v:.4f}" for i, v in enumerate(row)))
            fh.write("\n")


def main() -> None:
    import colour

    rng = np.random.default_rng(2013)

    def noisy(a):
        return np.clip(np.round(a + rng.normal(0.0, 0.001, np.shape(a)), 4), 0.0, 1.0)

    black = 0.035 + 0.01 * (WL - 380.0) / 400.0
    white = 0.86 + 0.06 * (WL - 380.0) / 400.0
    note = "synthetic example made by data/make_measurements.py (not a real product)"
    for name, (source, _, thicknesses) in PRODUCTS.items():
        S, K = true_spectra(name)
        comments = [f"name: {name}", note, f"mass tone: {source} (see make_measurements.py)"]
        if name == "blush_rose":  # raw radiance under D55 over a white card
            d55 = colour.SDS_ILLUMINANTS["D55"].copy().align(
                colour.SpectralShape(380, 780, 5)).values
            E_white = 0.012 * d55 * 0.99  # barium sulfate reflects ~99 %
            R, R_inf = simulate(S, K, thicknesses, white)
            _write(OUT / f"{name}.csv",
                   [*comments, f"thickness_mm: {thicknesses[0]}",
                    "radiance in W/(sr m^2 nm) under a D55 source"],
                   ["wavelength_nm", "E", "E_inf", "E_g", "E_white"],
                   [WL, noisy(R[0]) * E_white, noisy(R_inf) * E_white,
                    noisy(white) * E_white, E_white])
            continue
        R, R_inf = simulate(S, K, thicknesses, black)
        _write(OUT / f"{name}.csv", comments,
               ["wavelength_nm", *(f"R_{X:g}mm" for X in thicknesses), "R_inf", "R_g"],
               [WL, *(noisy(r) for r in R), noisy(R_inf), noisy(black)])


if __name__ == "__main__":
    main()
