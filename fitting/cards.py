"""Contrast cards (drawdowns): a film over a card's black and white parts (ASTM D2805,
ISO 6504-3; Leneta charts), for `jaxskin.fitting.km`.

Two backgrounds determine S·X and K·X of a film per band (Kubelka 1948, `km.two_backgrounds`)
without an opaque reading; this module holds what is particular to that layout: which bands
carry that information (`band_status`), the closed-form start (`closed_form`) and a start
for R∞ where the closed form has none (`r_inf_start`). Readings are the instrument's; with a
Saunderson correction (k1, k2) the closed form works on the internal reflectances
(`km.saunderson_inverse`).
"""

from __future__ import annotations

import numpy as np

from jaxskin import km

from .measurements import Measurement

__all__ = ["STATUS", "band_status", "closed_form", "internal", "r_inf_start"]

# A band's status, as `band_status` and the material JSON's `band_status` name it.
STATUS = {
    "identifiable": "the film over black and over white differ, and from the card: S and K",
    "opaque": "the film reads the same over black and over white (within 3√2σ): only K/S "
              "(R∞) is known",
    "too thin": "the film reads as the card's parts alone (within 3√2σ): nothing is known",
    "inconsistent": "the film is brighter over black than over white (by over 3√2σ), which no "
                    "film does: read as opaque, R∞ from both",
    "isolated": "identifiable, but in a run of fewer than 3 bands (noise): as opaque",
}


def internal(m: Measurement, saunderson=None):
    """The films' readings `R (m, n)`, the backgrounds under them `(m, n)` and R∞ (or None)
    as internal reflectances (`km.saunderson_inverse`; unchanged without `saunderson`)."""
    arrays = (m.R, m.backgrounds, m.R_inf)
    if saunderson is None:
        return arrays
    with np.errstate(all="ignore"):
        return tuple(None if a is None else np.asarray(km.saunderson_inverse(
            np.asarray(a, np.float64), float(saunderson[0]), float(saunderson[1])))
            for a in arrays)


def band_status(m: Measurement, noise: float, min_run: int = 3) -> np.ndarray:
    """Per band, one of `STATUS`'s keys: identifiable where some film differs over black and
    white and from a part of the card, in runs of `min_run` bands or more; inconsistent
    where a film is brighter over black than over white. Two readings differ when they do by
    more than 3√2 σ (σ = `noise`, each reading's: their difference has √2 σ), so that noise
    alone calls 0.1 % of opaque bands inconsistent, not 2 %."""
    tol = 3.0 * np.sqrt(2.0) * noise
    black, white = m.R[0::2], m.R[1::2]  # rows alternate: each film over black, then white
    diff = white - black
    seen = (np.abs(black - m.R_g) > tol) | (np.abs(white - m.R_g_white) > tol)
    ok = np.any((diff > tol) & seen, axis=0)
    bad = np.any(diff < -tol, axis=0)
    status = np.where(np.all(np.abs(diff) <= tol, axis=0), "opaque", "too thin").astype(object)
    status[ok] = "identifiable"
    status[bad] = "inconsistent"
    runs = _long_runs(status == "identifiable", min_run)
    status[(status == "identifiable") & ~runs] = "isolated"
    return status


def _long_runs(mask, n):
    """`mask` with its runs of True shorter than `n` set False."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    out = np.zeros_like(mask)
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        out[start:stop] = stop - start >= n
    return out


def closed_form(m: Measurement, saunderson=None) -> tuple[np.ndarray, np.ndarray]:
    """S and K (per mm; per film when the thickness is not known) from each film's two
    readings by Kubelka's two-background solution (`km.two_backgrounds`), averaged in log S
    and log K over the films; NaN where no film is inside the solution's domain."""
    import jax

    R, G, _ = internal(m, saunderson)
    logS, logK = [], []
    with jax.enable_x64(True), np.errstate(all="ignore"):
        for i in range(0, len(R), 2):
            R_inf, SX = (np.asarray(a) for a in km.two_backgrounds(R[i], R[i + 1], G[i],
                                                                  G[i + 1]))
            S = SX / m.thickness_mm[i]
            K = S * np.asarray(km.ks_from_r_inf(R_inf))
            ok = np.isfinite(S) & np.isfinite(K) & (S > 0) & (K > 0) & (R_inf < 1)
            logS.append(np.where(ok, np.log(np.where(ok, S, 1.0)), np.nan))
            logK.append(np.where(ok, np.log(np.where(ok, K, 1.0)), np.nan))
    out = []
    for v in (np.array(logS), np.array(logK)):
        count = np.sum(np.isfinite(v), axis=0)
        out.append(np.where(count > 0, np.exp(np.nansum(v, axis=0) / np.maximum(count, 1)),
                            np.nan))
    return out[0], out[1]


def r_inf_start(m: Measurement, saunderson=None) -> np.ndarray:
    """A start for R∞ per band (internal reflectance): the two-background solution where it
    holds, else the thickest film's two readings' mean (an opaque film reads R∞ over both),
    clipped into (1e-4, 1 − 1e-6)."""
    import jax

    R, G, R_inf = internal(m, saunderson)
    if R_inf is not None:
        return np.clip(R_inf, 1e-4, 1 - 1e-6)
    guess = 0.5 * (R[-2] + R[-1])
    with jax.enable_x64(True), np.errstate(all="ignore"):
        for i in range(0, len(R), 2):  # thinnest first: a thicker film's value wins
            solved = np.asarray(km.two_backgrounds(R[i], R[i + 1], G[i], G[i + 1])[0])
            guess = np.where(np.isfinite(solved), solved, guess)
    return np.clip(guess, 1e-4, 1 - 1e-6)
