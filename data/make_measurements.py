"""Make the example measurement CSVs in data/measurements/ (synthetic, not real products).

We have no spectroradiometer readings of real cosmetics we may ship, so these files are
made from chosen S(λ), K(λ) with the Kubelka–Munk forward model (jaxskin.km, float64), then
given instrument-like noise (σ = 0.001 in reflectance, 4 decimals) with a fixed seed. They
exercise every form the reader accepts: several thicknesses over a black card, a bare `R`
with `# thickness_mm:` over a white card as raw radiance (E_… and E_white under D55, the
paper's light), and a lipstick that is opaque below 600 nm (unidentifiable bands).

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


def true_spectra(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The chosen S(λ), K(λ) per mm behind each example (also used by the tests)."""
    x = WL
    if name == "foundation_beige":
        S = 12.0 * (550.0 / x)
        K = 0.25 + 5.0 * np.exp(-(x - 380.0) / 70.0) + 0.6 * np.exp(-(((x - 560.0) / 60.0) ** 2))
    elif name == "blush_rose":
        S = 6.0 * (550.0 / x) ** 1.5
        K = 0.2 + 9.0 * np.exp(-(((x - 540.0) / 45.0) ** 2)) + 3.0 * np.exp(-(x - 380.0) / 50.0)
    elif name == "lipstick_red":
        S = 9.0 * (550.0 / x)
        K = 0.4 + 40.0 / (1.0 + np.exp((x - 600.0) / 12.0))
    else:
        raise KeyError(name)
    return S, K


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
    rng = np.random.default_rng(2013)

    def noisy(a):
        return np.clip(np.round(a + rng.normal(0.0, 0.001, np.shape(a)), 4), 0.0, 1.0)

    black = 0.035 + 0.01 * (WL - 380.0) / 400.0
    white = 0.86 + 0.06 * (WL - 380.0) / 400.0
    note = "synthetic example made by data/make_measurements.py (not a real product)"

    S, K = true_spectra("foundation_beige")
    R, R_inf = simulate(S, K, [0.05, 0.15], black)
    _write(OUT / "foundation_beige.csv", ["name: foundation_beige", note],
           ["wavelength_nm", "R_0.05mm", "R_0.15mm", "R_inf", "R_g"],
           [WL, noisy(R[0]), noisy(R[1]), noisy(R_inf), noisy(black)])

    S, K = true_spectra("lipstick_red")
    R, R_inf = simulate(S, K, [0.1, 0.3], black)
    _write(OUT / "lipstick_red.csv", ["name: lipstick_red", note],
           ["wavelength_nm", "R_0.1mm", "R_0.3mm", "R_inf", "R_g"],
           [WL, noisy(R[0]), noisy(R[1]), noisy(R_inf), noisy(black)])

    # Raw radiance under D55 over a white card, thickness from the comment.
    import colour

    d55 = colour.SDS_ILLUMINANTS["D55"].copy().align(colour.SpectralShape(380, 780, 5)).values
    E_white = 0.012 * d55 * 0.99  # barium sulfate reflects ~99 %
    S, K = true_spectra("blush_rose")
    R, R_inf = simulate(S, K, [0.08], white)
    _write(OUT / "blush_rose.csv", ["name: blush_rose", "thickness_mm: 0.08", note,
                                    "radiance in W/(sr m^2 nm) under a D55 source"],
           ["wavelength_nm", "E", "E_inf", "E_g", "E_white"],
           [WL, noisy(R[0]) * E_white, noisy(R_inf) * E_white, noisy(white) * E_white,
            E_white])


if __name__ == "__main__":
    main()
