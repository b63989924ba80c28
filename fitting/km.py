"""Scattering S(λ) and absorption K(λ) of a cosmetic from reflectance measurements.

Huang et al. 2013 §4: a thin layer over a background (R), an opaque layer (R∞) and the
background alone (Rg). The closed form (eq. 6–7) gives a start where its domain holds;
Levenberg–Marquardt (optimistix, float64) then fits log S and log K at every band at once,
to every thin-layer thickness and to R∞ together, optionally with a smoothness prior across
bands.

Identifiability: where the thin layer is as good as opaque (|R − R∞| <= 3σ, σ the noise of
one reading) or the background is as bright as the opaque layer (|Rg − R∞| <= 3σ), the band
carries no thickness information: only K/S is known there. Such bands keep K/S from the fit
to R∞, take S from the identifiable neighbours (linear in log S), and are marked
`identifiable = False`.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from jaxskin import km
from jaxskin.io import InputError

from .measurements import Measurement

__all__ = ["KMFit", "closed_form", "fit", "identifiable", "model_reflectance"]

DEFAULT_NOISE = 0.002  # σ of one reflectance reading
NOISE_SIGMAS = 3.0  # a difference counts when it exceeds this many σ


@dataclasses.dataclass(frozen=True)
class KMFit:
    """The result of `fit`: per-band S, K (per mm) and how well they reproduce the data."""

    name: str
    wavelength_nm: np.ndarray
    S_per_mm: np.ndarray
    K_per_mm: np.ndarray
    identifiable: np.ndarray
    rmse: float
    R_fit: np.ndarray  # (m, n): the model's thin-layer reflectances
    R_inf_fit: np.ndarray
    S_closed: np.ndarray  # NaN where the closed form is outside its domain
    K_closed: np.ndarray
    steps: int
    converged: bool
    smooth: float
    noise: float

    def to_json(self, measurement: Measurement) -> dict:
        """The material file: what `jaxskin` reads for a cosmetic layer, plus the fit's record."""

        def clean(a):
            return [None if not np.isfinite(v) else float(v) for v in np.asarray(a)]

        return {
            "name": self.name,
            "model": "kubelka-munk",
            "wavelength_nm": clean(self.wavelength_nm),
            "S_per_mm": clean(self.S_per_mm),
            "K_per_mm": clean(self.K_per_mm),
            "identifiable": [bool(v) for v in self.identifiable],
            "rmse": float(self.rmse),
            "fit": {
                "source": measurement.path.name,
                "thickness_mm": clean(measurement.thickness_mm),
                "method": "closed form (Huang et al. 2013 eq. 6-7) then Levenberg-Marquardt "
                "on log S, log K (optimistix, float64)",
                "smooth": self.smooth,
                "noise": self.noise,
                "steps": int(self.steps),
                "converged": bool(self.converged),
                "S_closed_form_per_mm": clean(self.S_closed),
                "K_closed_form_per_mm": clean(self.K_closed),
            },
        }


def identifiable(m: Measurement, noise: float = DEFAULT_NOISE) -> np.ndarray:
    """Bands where S and K can be told apart: some thin layer differs from R∞ by more than 3σ
    (`noise` = σ, the standard deviation of one reading) and so does the background."""
    thin = np.max(np.abs(m.R - m.R_inf), axis=0) > NOISE_SIGMAS * noise
    background = np.abs(m.R_g - m.R_inf) > NOISE_SIGMAS * noise
    return thin & background


def closed_form(m: Measurement) -> tuple[np.ndarray, np.ndarray]:
    """S and K from eq. 6–7, averaged (in log S) over the thin layers; NaN outside the domain.

    With L(R) = ½ ln|(1/R∞ − R)/(R∞ − R)| (arcoth for a black background, artanh for a white
    one, which the absolute value unifies), b S X = L(R) − L(Rg). Valid when R lies strictly
    between Rg and R∞ and 0 < R∞ < 1.
    """
    R_inf = m.R_inf
    with np.errstate(divide="ignore", invalid="ignore"):
        a = 0.5 * (1.0 / R_inf + R_inf)
        b = np.sqrt(a * a - 1.0)

        def L(R):
            return 0.5 * np.log(np.abs((1.0 / R_inf - R) / (R_inf - R)))

        logS = []
        for X, R in zip(m.thickness_mm, m.R, strict=True):
            inside = (np.abs(R - R_inf) < np.abs(m.R_g - R_inf)) & (
                np.sign(R - R_inf) == np.sign(m.R_g - R_inf)
            )
            S = (L(R) - L(m.R_g)) / (b * X)
            ok = inside & (R_inf > 0) & (R_inf < 1) & np.isfinite(S) & (S > 0)
            logS.append(np.where(ok, np.log(np.where(ok, S, 1.0)), np.nan))
        logS = np.array(logS)
        count = np.sum(np.isfinite(logS), axis=0)
        S = np.where(count > 0, np.exp(np.nansum(logS, axis=0) / np.maximum(count, 1)), np.nan)
        K = S * (a - 1.0)
    return S, K


def model_reflectance(logS, logK, X, Rg):
    """The model behind the fit: R of layers of thickness `X (m,)` over `Rg (n,)`, and R∞.

    **Returns:** `(R (m, n), R_inf (n,))`.
    """
    S, K = jnp.exp(logS), jnp.exp(logK)
    R0, T = km.layer(S, K, X[:, None])
    return km.over(R0, T, Rg), km.r_inf(S, K)


def _residuals(y, args):
    logS, logK = y
    X, R, R_inf, Rg, prior, ident, logS_fixed = args
    # Where S is not identifiable it is held (a zero Jacobian column), so it cannot drift.
    logS = jnp.where(ident, logS, logS_fixed)
    R_model, R_inf_model = model_reflectance(logS, logK, X, Rg)
    return (
        (R_model - R).ravel(),
        R_inf_model - R_inf,
        prior * jnp.diff(logS),
        prior * jnp.diff(logK),
    )


@functools.partial(jax.jit, static_argnames=("max_steps",))
def _solve(y0, args, max_steps=256):
    solver = optx.LevenbergMarquardt(rtol=1e-9, atol=1e-12)
    sol = optx.least_squares(_residuals, solver, y0, args, max_steps=max_steps, throw=False)
    # Only arrays leave the jit (optimistix issue 63: a whole Solution does not vmap).
    return sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]


def fit(m: Measurement, smooth: float = 0.0, noise: float = DEFAULT_NOISE) -> KMFit:
    """Fit S(λ), K(λ) to one measurement.

    **Arguments:**

    - `m`: the measurement (`read_measurement`).
    - `smooth`: W of a Gaussian prior that neighbouring bands' log S and log K differ by about
      1/W (standard deviation), weighed against readings of σ = `noise`: the maximum a
      posteriori fit. 0 (default) fits each band on its own; W = 20 allows ~5 % per band.
    - `noise`: σ of one reflectance reading; differences within 3σ count as equal when
      deciding which bands are identifiable.

    **Returns:** a `KMFit`. **Raises:** `InputError` if no band is identifiable.
    """
    ident = identifiable(m, noise)
    if not ident.any():
        raise InputError(
            f"no band where S can be separated from K: every thin layer is within 3 x --noise "
            f"{noise:g} of R_inf (opaque) or R_g is; measure a thinner layer or a background "
            "further from R_inf", m.path, m.header_line, m.columns[0],
        )
    S_cf, K_cf = closed_form(m)
    wl = m.wavelength_nm
    # Start: the closed form where valid; elsewhere log S from valid neighbours, K/S from R∞.
    valid = np.isfinite(S_cf) & ident
    if valid.any():
        logS0 = np.interp(wl, wl[valid], np.log(S_cf[valid]))
    else:
        logS0 = np.full_like(wl, -np.log(np.mean(m.thickness_mm)))
    ratio = np.asarray(km.ks_from_r_inf(np.clip(m.R_inf, 1e-4, 1 - 1e-6)))
    logK0 = np.where(valid, np.log(np.where(valid, K_cf, 1.0)), logS0 + np.log(ratio))

    with jax.enable_x64(True):
        f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
        data = (f64(m.thickness_mm), f64(m.R), f64(m.R_inf), f64(m.R_g), f64(smooth * noise),
                jnp.asarray(ident))
        (logS, logK), ok, steps = _solve((f64(logS0), f64(logK0)), (*data, f64(logS0)))
        if not ident.all():
            # S where it is not identifiable: from the fitted neighbours (linear in log S),
            # K/S kept; then fit again with S held there, so S, K and the fit agree.
            logS_fill = np.interp(wl, wl[ident], np.asarray(logS)[ident])
            y = (f64(logS_fill), f64(logS_fill) + logK - logS)
            (logS, logK), ok, more = _solve(y, (*data, f64(logS_fill)))
            steps = steps + more
        logS, logK = (np.asarray(a) for a in (logS, logK))
        R_fit, R_inf_fit = (np.asarray(a) for a in model_reflectance(f64(logS), f64(logK),
                                                                      data[0], data[3]))
    residual = np.concatenate([(R_fit - m.R).ravel(), R_inf_fit - m.R_inf])
    return KMFit(
        name=m.name, wavelength_nm=wl, S_per_mm=np.exp(logS), K_per_mm=np.exp(logK),
        identifiable=ident, rmse=float(np.sqrt(np.mean(residual**2))), R_fit=R_fit,
        R_inf_fit=R_inf_fit, S_closed=S_cf, K_closed=K_cf, steps=int(steps),
        converged=bool(ok), smooth=float(smooth), noise=float(noise),
    )

