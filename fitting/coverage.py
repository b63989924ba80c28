"""What a formulator reads first: a film's contrast ratio, its thickness for 98 % hiding and
the colour difference between it over black and over white, from fitted S(λ), K(λ).

- Colour: CIE XYZ under D65 with the CIE 1964 10° observer (what paint and cosmetics labs
  report), integrated every 1 nm over 380–780 nm, the reflectance interpolated linearly
  (held at its end values beyond the measured range), normalised so that a perfect
  reflector has Y = 1; CIELAB against that white; ΔE by CIEDE2000 (colour-science).
- Contrast ratio C = Y over black / Y over white (ASTM D2805, ISO 6504). As ASTM D2805
  defines it for hiding power, the backgrounds are standard: an ideal black (0) and a white
  of reflectance 0.80 (flat), under the film (`STANDARD_BLACK`, `STANDARD_WHITE`); so a
  figure does not depend on the card a lab happened to use. A contrast card's own readings
  give the measured C beside it.
- Hiding thickness: the film thickness at which C = 0.98 (D2805's hiding end point), from
  S and K (C rises with thickness towards 1). Where the thickness was not measured, S and K
  are per film and the figure is in multiples of the film as measured.
"""

from __future__ import annotations

import functools

import numpy as np

from jaxskin import km

from .measurements import Measurement

__all__ = ["HIDING", "STANDARD_BLACK", "STANDARD_WHITE", "contrast_ratio", "coverage",
           "delta_e2000", "hiding_thickness", "lab", "xyz"]

STANDARD_BLACK = 0.0  # ASTM D2805's backgrounds for the contrast ratio C = R0 / R0.80
STANDARD_WHITE = 0.80
HIDING = 0.98  # the contrast ratio of complete hiding (ASTM D2805, ISO 6504-1)


@functools.cache
def _weights() -> tuple[np.ndarray, np.ndarray]:
    """1 nm wavelengths 380–780 and `(401, 3)` weights E(λ)·x̄ȳz̄(λ) / Σ E ȳ (D65, 10°)."""
    import colour

    wl = np.arange(380.0, 781.0)
    cmfs = colour.MSDS_CMFS["CIE 1964 10 Degree Standard Observer"]
    d65 = colour.SDS_ILLUMINANTS["D65"]
    E = np.interp(wl, d65.wavelengths, d65.values)  # tabulated every 5 nm: linear between
    W = E[:, None] * np.asarray(cmfs[wl])
    W = W / W[:, 1].sum()
    W.setflags(write=False)
    return wl, W


def xyz(R, wavelength_nm) -> np.ndarray:
    """CIE XYZ `(..., 3)` (D65, 10°; white Y = 1) of reflectances `R (..., n)` at
    `wavelength_nm (n,)`."""
    wl, W = _weights()
    R = np.asarray(R, np.float64)
    fine = np.apply_along_axis(lambda r: np.interp(wl, wavelength_nm, r), -1, R)
    return fine @ W


def lab(XYZ) -> np.ndarray:
    """CIELAB of `XYZ (..., 3)` against the perfect reflector's XYZ (D65, 10°)."""
    import colour

    _, W = _weights()
    white = W.sum(axis=0)
    return np.asarray(colour.XYZ_to_Lab(np.asarray(XYZ) / white[1],
                                        colour.XYZ_to_xy(white)))


def delta_e2000(R1, R2, wavelength_nm) -> np.ndarray:
    """CIEDE2000 between reflectances `R1` and `R2` `(..., n)` (D65, 10°)."""
    import colour

    return np.asarray(colour.delta_E(lab(xyz(R1, wavelength_nm)), lab(xyz(R2, wavelength_nm)),
                                     method="CIE 2000"))


def _over(S, K, X, Rg, saunderson):
    """The film's reflectance `X` thick over `Rg`, as the instrument reads it."""
    import jax

    with jax.enable_x64(True):
        R = km.over(*km.layer(np.asarray(S, np.float64), np.asarray(K, np.float64),
                              np.asarray(X, np.float64)), np.asarray(Rg, np.float64))
        if saunderson is not None:
            R = km.saunderson(R, *saunderson)
        return np.asarray(R)


def contrast_ratio(S, K, X, wavelength_nm, black=STANDARD_BLACK, white=STANDARD_WHITE,
                   saunderson=None) -> float:
    """Y over `black` / Y over `white` of a film `X` thick (mm; or films, when S and K are
    per film) with `S`, `K (n,)`, backgrounds internal reflectances (scalars or `(n,)`)."""
    Yb = xyz(_over(S, K, X, black, saunderson), wavelength_nm)[1]
    Yw = xyz(_over(S, K, X, white, saunderson), wavelength_nm)[1]
    return float(Yb / Yw)


def hiding_thickness(S, K, wavelength_nm, black=STANDARD_BLACK, white=STANDARD_WHITE,
                     saunderson=None, target=HIDING, start=1e-3) -> float | None:
    """The thickness at which `contrast_ratio` reaches `target` (0.98): the first crossing
    on a doubling ladder from `start` / 2²⁰ up to `start` · 2⁴⁰, then bisection in log X to
    1e-9 relative. None where the ladder's ends are both above or both below the target."""
    def c(x):
        return contrast_ratio(S, K, x, wavelength_nm, black, white, saunderson)

    ladder = start * 2.0 ** np.arange(-20, 41)
    values = [c(x) for x in ladder[:1]]
    for x in ladder[1:]:
        values.append(c(x))
        if values[-1] >= target:
            break
    if values[0] >= target or values[-1] < target:
        return None
    lo, hi = np.log(ladder[len(values) - 2]), np.log(ladder[len(values) - 1])
    while hi - lo > 1e-9:
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if c(np.exp(mid)) < target else (lo, mid)
    return float(np.exp(0.5 * (lo + hi)))


def coverage(m: Measurement, S, K, saunderson=None) -> dict:
    """The coverage figures of a film with fitted `S`, `K (n,)` measured as `m`: per film
    thickness, the contrast ratio and ΔE2000 over ASTM D2805's black and white (and for a
    contrast card the measured ones on its parts), and the thickness for 98 % hiding.

    **Returns:** the material JSON's `coverage` block (Python numbers; None where a figure
    does not exist)."""
    wl = m.wavelength_nm
    films = []
    for i, X in enumerate(m.thickness_mm):
        if m.is_card and m.over[i] != "black":
            continue
        if not m.is_card and i and X == m.thickness_mm[i - 1]:
            continue
        over = [_over(S, K, X, b, saunderson) for b in (STANDARD_BLACK, STANDARD_WHITE)]
        film = {"thickness_mm": float(X) if m.thickness_known else None,
                "contrast_ratio": contrast_ratio(S, K, X, wl, saunderson=saunderson),
                "delta_E2000": float(delta_e2000(*over, wl))}
        if m.is_card:  # the card's own readings: what the lab's instrument shows
            Rb, Rw = m.R[i], m.R[i + 1]
            film["contrast_ratio_card"] = float(xyz(Rb, wl)[1] / xyz(Rw, wl)[1])
            film["delta_E2000_card"] = float(delta_e2000(Rb, Rw, wl))
        films.append(film)
    X98 = hiding_thickness(S, K, wl, saunderson=saunderson,
                           start=float(np.min(m.thickness_mm)))
    out = {
        "illuminant": "D65",
        "observer": "CIE 1964 10 degree",
        "backgrounds": f"ASTM D2805: black {STANDARD_BLACK:g}, white {STANDARD_WHITE:g} "
                       "under the film",
        "films": films,
    }
    if m.thickness_known:
        out["hiding_98_mm"] = X98
    else:
        out["hiding_98_films"] = X98  # S, K are per film: X98 in films as measured
        out["note"] = ("the film's thickness was not given: hiding_98_films is the "
                       "thickness for a contrast ratio of 0.98 in multiples of the film "
                       "as measured")
    return out
