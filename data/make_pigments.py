"""Make the example pigment measurements in data/pigments/ (synthetic, from stated S, K).

A foundation is a white base (titanium dioxide in a cream) tinted with iron oxides: red
(haematite), yellow (goethite) and black (magnetite). We have no measurements of real
pigments we may ship, so these four files are made from the S(λ), K(λ) per mm below with
the Kubelka–Munk forward model (jaxskin.km, float64), plus σ = 0.001 instrument noise
(4 decimals, seed 2026), in the layout `jaxskin calibrate` reads: two thin layers over a
card, an opaque layer, the card (black under the white pigment, white under the dark ones,
so that the card shows through in every band). The shapes are chosen to look like the pigments'
(absorption edges where the real ones have them), not measured:

- `pigment_white`: S = 300 (550/λ)^1.5 (small particles scatter blue more), K = 0.3 +
  200 / (1 + exp((λ − 400)/8)) (titanium dioxide's band edge near 400 nm);
- `pigment_red`: S = 60 (550/λ), K = 6 + 900 / (1 + exp((λ − 585)/16)) (haematite
  absorbs below about 590 nm);
- `pigment_yellow`: S = 80 (550/λ), K = 4 + 700 / (1 + exp((λ − 505)/18)) (goethite's
  edge near 500 nm);
- `pigment_black`: S = 15, K = 900 − 0.4 (λ − 380) (magnetite absorbs everywhere).

    python data/make_pigments.py      # rewrites data/pigments/*.csv
    jaxskin calibrate data/pigments/*.csv -o data/materials
"""

from __future__ import annotations

from pathlib import Path

import jax
import numpy as np

from jaxskin import km
from jaxskin.io import atomic_write

WL = np.arange(380.0, 781.0, 5.0)
OUT = Path(__file__).resolve().parent / "pigments"
# Thin layers (mm) per pigment: thin enough that the card shows through in most bands.
THICKNESSES = {"pigment_white": (0.002, 0.006), "pigment_red": (0.002, 0.006),
               "pigment_yellow": (0.002, 0.006), "pigment_black": (0.001, 0.003)}


def true_spectra(name: str) -> tuple[np.ndarray, np.ndarray]:
    """The chosen S(λ), K(λ) per mm of each pigment (also used by the tests)."""
    x = WL
    if name == "pigment_white":
        return 300.0 * (550.0 / x) ** 1.5, 0.3 + 200.0 / (1.0 + np.exp((x - 400.0) / 8.0))
    if name == "pigment_red":
        return 60.0 * (550.0 / x), 6.0 + 900.0 / (1.0 + np.exp((x - 585.0) / 16.0))
    if name == "pigment_yellow":
        return 80.0 * (550.0 / x), 4.0 + 700.0 / (1.0 + np.exp((x - 505.0) / 18.0))
    if name == "pigment_black":
        return np.full_like(x, 15.0), 900.0 - 0.4 * (x - 380.0)
    raise KeyError(name)


def main() -> None:
    rng = np.random.default_rng(2026)
    black = 0.035 + 0.01 * (WL - 380.0) / 400.0
    white = 0.86 + 0.06 * (WL - 380.0) / 400.0
    OUT.mkdir(exist_ok=True)
    for name, thicknesses in THICKNESSES.items():
        S, K = true_spectra(name)
        card = black if name == "pigment_white" else white
        with jax.enable_x64(True):
            R = [np.asarray(km.over(*km.layer(S, K, X), card)) for X in thicknesses]
            R_inf = np.asarray(km.r_inf(S, K))
        columns = [WL, *R, R_inf, card]
        noisy = [WL] + [np.clip(np.round(c + rng.normal(0.0, 0.001, c.shape), 4), 0.0, 1.0)
                        for c in columns[1:]]
        header = ["wavelength_nm", *(f"R_{X:g}mm" for X in thicknesses), "R_inf", "R_g"]
        with atomic_write(OUT / f"{name}.csv", "w") as fh:
            fh.write(f"# name: {name}\n# synthetic example made by data/make_pigments.py "
                     "(not a real pigment)\n")
            fh.write(",".join(header) + "\n")
            for row in zip(*noisy, strict=True):
                fh.write(",".join(f"{v:.0f}" if i == 0 else f"{v:.4f}"
                                  for i, v in enumerate(row)) + "\n")


if __name__ == "__main__":
    main()
