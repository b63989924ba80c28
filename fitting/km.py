"""Scattering S(λ) and absorption K(λ) of a cosmetic from reflectance measurements.

Huang et al. 2013 §4: a thin layer over a background (R), an opaque layer (R∞) and the
background alone (Rg). The closed form (eq. 6–7) gives a start where its domain holds;
Levenberg–Marquardt (float64) then fits log S and log K to every thin-layer thickness and to
R∞ together, optionally with a smoothness prior across bands. The problem is separable per
band apart from the prior: without it each band's two-parameter problem is solved on its own
(vmapped over bands); with it the normal equations are block-tridiagonal (2×2 blocks) and are
solved by block elimination in a scan. Time and memory are O(bands) either way.
`solver="dense"` keeps the earlier solver (optimistix over all bands, a dense Jacobian: O(n²)
memory) as a reference.

Identifiability: where the thin layer is as good as opaque (|R − R∞| <= 3σ, σ the noise of
one reading) or the background is as bright as the opaque layer (|Rg − R∞| <= 3σ), the band
carries no thickness information: only K/S is known there; so are identifiable bands in a
run shorter than `MIN_RUN` (noise lifts a lone band over 3σ now and then).
Such bands keep K/S from the fit to R∞, take S from the identifiable neighbours (linear in
log S), and are marked `identifiable = False`.
"""

from __future__ import annotations

import dataclasses
import functools

import jax
import jax.numpy as jnp
import numpy as np
import optimistix as optx

from jaxskin import km
from jaxskin.formats import MAX_SK_PER_MM
from jaxskin.io import FitError, InputError
from jaxskin.precision import einsum, matmul

from . import cards
from .measurements import Measurement

__all__ = ["KMFit", "closed_form", "fit", "identifiable", "model_reflectance", "suspect_labels"]

DEFAULT_NOISE = 0.002  # σ of one reflectance reading
MAX_NOISE = 0.5  # σ beyond this is not a reflectance measurement
MAX_SMOOTH = 1e6  # 1/W = 1e-6 per band: already a constant spectrum
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
    status: np.ndarray | None = None  # a contrast card's `cards.band_status`
    saunderson: tuple[float, float] | None = None
    thickness_known: bool = True  # False: S_per_mm, K_per_mm are S·X, K·X of the film
    coverage: dict | None = None  # `coverage.coverage`

    def to_json(self, measurement: Measurement, extrapolate: str | None = None) -> dict:
        """The material file: what `jaxskin` reads for a cosmetic layer, plus the fit's record.
        `extrapolate` ("hold", "linear" or None) says how a renderer may extend S and K
        beyond the measured wavelengths (`cosmetics.load_material`)."""

        def clean(a):
            return [None if not np.isfinite(v) else float(v) for v in np.asarray(a)]

        card = measurement.is_card
        if self.thickness_known:
            sk = {"S_per_mm": clean(self.S_per_mm), "K_per_mm": clean(self.K_per_mm)}
        else:  # S·X and K·X of the film: unknown where S cannot be told from K
            sk = {"S_film": clean(np.where(self.identifiable, self.S_per_mm, np.nan)),
                  "K_film": clean(np.where(self.identifiable, self.K_per_mm, np.nan)),
                  "note": "the film's thickness was not given: S_film and K_film are S*X and "
                  "K*X of the film as measured (null where S and K cannot be told apart); "
                  "calibrate with --thickness MM (or '# thickness_mm:') for S_per_mm and "
                  "K_per_mm, which a scene needs"}
        method = ("closed form (Huang et al. 2013 eq. 6-7) then Levenberg-Marquardt on log S, "
                  "log K (float64; per band, or block-tridiagonal with the prior)")
        if card:
            method = ("contrast card: Kubelka's (1948) two-background closed form, then "
                      "Levenberg-Marquardt on log S, log K over every film on both parts of "
                      "the card (float64; per band, or block-tridiagonal with the prior)")
        per = "per_mm" if self.thickness_known else "film"
        return {
            "name": self.name,
            "model": "kubelka-munk",
            "wavelength_nm": clean(self.wavelength_nm),
            **sk,
            "identifiable": [bool(v) for v in self.identifiable],
            **({"band_status": [str(v) for v in self.status]} if self.status is not None
               else {}),
            **({"R_inf": clean(self.R_inf_fit)} if card else {}),
            "rmse": float(self.rmse),
            **({"extrapolate": extrapolate} if extrapolate else {}),
            **({"coverage": self.coverage} if self.coverage is not None else {}),
            "fit": {
                "source": measurement.path.name,
                "thickness_mm": (clean(measurement.thickness_mm) if self.thickness_known
                                 else None),
                **({"layout": "contrast card", "over": list(measurement.over)} if card
                   else {}),
                "method": method,
                **({"saunderson": list(self.saunderson)} if self.saunderson else {}),
                "smooth": self.smooth,
                "noise": self.noise,
                "steps": int(self.steps),
                "converged": bool(self.converged),
                f"S_closed_form_{per}": clean(self.S_closed),
                f"K_closed_form_{per}": clean(self.K_closed),
            },
        }


def identifiable(m: Measurement, noise: float = DEFAULT_NOISE) -> np.ndarray:
    """Bands where S and K can be told apart: some thin layer differs from R∞ by more than 3σ
    (`noise` = σ, the standard deviation of one reading) and so does the background. On a
    contrast card: the bands `cards.band_status` calls identifiable."""
    if m.is_card:
        return cards.band_status(m, noise, MIN_RUN) == "identifiable"
    thin = np.max(np.abs(m.R - m.R_inf), axis=0) > NOISE_SIGMAS * noise
    background = np.abs(m.R_g - m.R_inf) > NOISE_SIGMAS * noise
    return _runs(thin & background, MIN_RUN)


# Identifiable bands count in runs of at least this many (`_runs`): noise
# alone lifts a band over 3σ now and then (0.3 % of readings), and such a lone band, its S
# fitted to noise, would anchor the interpolation of log S across its neighbours (a noisy
# 1 nm lipstick gave S 1.7 /mm at 426 nm where the truth is 140: a magenta blush). Real
# spectra change smoothly: an identifiable stretch spans many bands.
MIN_RUN = 3


def _runs(mask: np.ndarray, n: int) -> np.ndarray:
    """`mask` with its runs of True shorter than `n` set False (all of it kept if that would
    leave none)."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], mask.astype(np.int8), [0]])))
    out = np.zeros_like(mask)
    for start, stop in zip(edges[::2], edges[1::2], strict=True):
        out[start:stop] = stop - start >= n
    return out if out.any() else mask


def suspect_labels(m: Measurement, noise: float = DEFAULT_NOISE) -> list[str]:
    """Readings in an order the model cannot produce, as one line each (empty: none).

    A layer over the background reflects between R_g (no layer) and R_inf (opaque), the
    nearer R_inf the thicker it is. A thin layer on the other side of R_inf, or further from
    it than R_g or than a thinner layer, breaks that: columns swapped or mislabelled. Each
    rule is reported when it is broken by more than 3σ at more bands than it visibly holds
    at (by more than 3σ) and at 10 % of the bands or 5, whichever is more, so noise alone
    does not trigger it.
    """
    if m.is_card:  # a card's bands say it themselves: `cards.band_status`
        return []
    tol = NOISE_SIGMAS * noise
    towards_g = np.sign(m.R_g - m.R_inf)
    # Distance from R_inf, positive on R_g's side: R_g, then the thin layers, thinnest first.
    d = [(R - m.R_inf) * towards_g for R in (m.R_g, *m.R)]
    names = ["R_g", *m.columns]
    n = len(m.wavelength_nm)
    # Noise alone breaks a 3σ rule at ~1.7 % of bands where the two readings are equal in
    # truth (an opaque layer beside R_inf): fewer than this many broken bands say nothing.
    floor = max(5, int(0.1 * n))
    lines = []
    for k, column in enumerate(m.columns, start=1):  # one line per column at most
        other_side = np.sum(d[k] < -tol), np.sum(d[k] > tol)
        further = np.sum(d[k] - d[k - 1] > tol), np.sum(d[k - 1] - d[k] > tol)
        if other_side[0] > other_side[1] and other_side[0] >= floor:
            lines.append(f"{m.path}: column '{column}' lies on the other side of R_inf from R_g "
                         f"at {other_side[0]} of {n} bands, where a layer over the background "
                         "reflects between the two: R_inf and a thin layer swapped?")
        elif further[0] > further[1] and further[0] >= floor:
            lines.append(f"{m.path}: column '{column}' is further from R_inf than "
                         f"'{names[k - 1]}' at {further[0]} of {n} bands, where a thicker layer "
                         "lies nearer R_inf: columns swapped or thicknesses mislabelled?")
    return lines


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


def model_reflectance(logS, logK, X, Rg, saunderson=None):
    """The model behind the fit: R of layers of thickness `X (m,)` over `Rg (n,)` (or one
    background per layer, `(m, n)`: a contrast card), and R∞; as the instrument reads them
    (`km.saunderson`) when `saunderson` = (k1, k2) is given, Rg then being the backgrounds'
    internal reflectance.

    **Returns:** `(R (m, n), R_inf (n,))`.
    """
    S, K = jnp.exp(logS), jnp.exp(logK)
    R0, T = km.layer(S, K, X[:, None])
    return _seen(km.over(R0, T, Rg), saunderson), _seen(km.r_inf(S, K), saunderson)


def _seen(R, saunderson):
    """An internal reflectance as the instrument reads it (unchanged without Saunderson)."""
    return R if saunderson is None else km.saunderson(R, saunderson[0], saunderson[1])


def _band_residuals(y, X, R, R_inf, Rg, sd=None):
    """One band's residuals `(m + 1,)`: the thin layers' model minus data, then R∞'s (`(m,)`
    where there is no R∞ reading, `R_inf` None)."""
    S, K = jnp.exp(y[0]), jnp.exp(y[1])
    R0, T = km.layer(S, K, X)
    r = _seen(km.over(R0, T, Rg), sd) - R
    return r if R_inf is None else jnp.append(r, _seen(km.r_inf(S, K), sd) - R_inf)


def _linearise(y, args):
    """Residuals `r (n, m + 1)` and their Jacobian `J (n, m + 1, 2)` per band, at `y (n, 2)`
    with S held where it is not identifiable (its Jacobian column is 0 there)."""
    X, R, R_inf, Rg, _, ident, logS_fixed, sd = args
    y = y.at[:, 0].set(jnp.where(ident, y[:, 0], logS_fixed))

    def one(yb, Rb, Rib, Rgb):
        f = functools.partial(_band_residuals, X=X, R=Rb, R_inf=Rib, Rg=Rgb, sd=sd)
        return f(yb), jax.jacfwd(f)(yb)

    r, J = jax.vmap(one)(y, R, R_inf, Rg)
    return y, r, J * jnp.stack([ident, jnp.ones_like(ident)], -1)[:, None, :]


def _cost(y, args):
    """½ (Σ r² + prior² Σ (Δ log S)² + prior² Σ (Δ log K)²): what `_solve` minimises."""
    prior = args[4]
    y, r, _ = _linearise(y, args)
    return 0.5 * (jnp.sum(r * r) + prior**2 * jnp.sum(jnp.diff(y, axis=0) ** 2))


def _normal_equations(y, args):
    """At `y (n, 2)`: the cost (`_cost`), its gradient `g (n, 2)` and the data's Gauss–Newton
    blocks `H (n, 2, 2)` = Jᵀ J per band (the prior's part is added by the solver)."""
    prior, ident = args[4], args[5]
    y_eff, r, J = _linearise(y, args)
    diff = jnp.diff(y_eff, axis=0)
    pad = jnp.zeros((1, 2), y.dtype)
    g_prior = (jnp.concatenate([pad, diff]) - jnp.concatenate([diff, pad])) * jnp.stack(
        [ident, jnp.ones_like(ident)], -1)
    g = einsum("nri,nr->ni", J, r) + prior**2 * g_prior
    H = einsum("nri,nrj->nij", J, J)
    return 0.5 * (jnp.sum(r * r) + prior**2 * jnp.sum(diff**2)), g, H


def block_tridiagonal_solve(D, off, b):
    """Solve the symmetric block-tridiagonal system with 2×2 diagonal blocks `D (n, 2, 2)`,
    diagonal 2×2 off-diagonal blocks `off (n - 1, 2)` (their diagonals) and `b (n, 2)`:
    block Thomas elimination, O(n) time and memory (a scan). Stable without pivoting for a
    positive-definite matrix (every Schur complement is then positive definite).

    **Returns:** `x (n, 2)`.
    """
    zero = jnp.zeros((1, 2), D.dtype)
    above, below = jnp.concatenate([off, zero]), jnp.concatenate([zero, off])

    def forward(carry, block):
        C_prev, d_prev = carry
        Dj, up, low, bj = block
        Dj = Dj - low[:, None] * C_prev
        inv = _inverse2(Dj)
        C, d = inv * up[None, :], matmul(inv, bj - low * d_prev)
        return (C, d), (C, d)

    init = (jnp.zeros((2, 2), D.dtype), jnp.zeros(2, D.dtype))
    _, (C, d) = jax.lax.scan(forward, init, (D, above, below, b))

    def backward(x_next, block):
        Cj, dj = block
        x = dj - matmul(Cj, x_next)
        return x, x

    _, x = jax.lax.scan(backward, jnp.zeros(2, D.dtype), (C, d), reverse=True)
    return x


def _inverse2(M):
    a, b, c, d = M[0, 0], M[0, 1], M[1, 0], M[1, 1]
    return jnp.array([[d, -b], [-c, a]]) / (a * d - b * c)


def _solve_banded(y0, args, max_steps=256, rtol=1e-9, atol=1e-12):
    """Levenberg–Marquardt on `y (n, 2)` = (log S, log K) per band, with the normal
    equations solved block-tridiagonally: the data couple log S and log K within a band
    (a 2×2 block), the prior only neighbouring bands' same variable. Damping μ by Nielsen's
    rule (Madsen, Nielsen, Tingleff 2004, §3.2); stops when an accepted step moves no
    variable by more than `atol + rtol |y|` and lowers the cost by less than
    `atol + rtol · cost`, or such a step is rejected and was predicted to gain no more
    (the cost at its rounding floor), or no decrease is predicted at all (all: converged);
    when μ passes 1e30 (stuck: not converged); or after `max_steps`.

    **Returns:** `(y, converged, steps)`.
    """
    prior, ident = args[4], args[5]
    mask = jnp.stack([ident, jnp.ones_like(ident)], -1).astype(y0.dtype)  # free variables
    links = mask[1:] * mask[:-1]  # the prior's neighbour terms on free variables
    count = jnp.concatenate([links, jnp.zeros((1, 2), y0.dtype)]) + jnp.concatenate(
        [jnp.zeros((1, 2), y0.dtype), links])

    normal_equations = functools.partial(_normal_equations, args=args)

    def step(state):
        y, cost, g, H, mu, nu, k, done, ok = state
        D = H + (prior**2 * count + mu)[:, :, None] * jnp.eye(2, dtype=y.dtype)
        if y.shape[0] == 1:  # one band (the separable case): a 2×2 solve, no scan
            delta = -matmul(_inverse2(D[0]), g[0])[None]
        else:
            delta = block_tridiagonal_solve(D, -prior**2 * links, -g)
        y_new = y + delta
        cost_new, g_new, H_new = normal_equations(y_new)
        predicted = 0.5 * jnp.sum(delta * (mu * delta - g))
        rho = (cost - cost_new) / jnp.where(predicted > 0, predicted, 1.0)
        accept = (predicted > 0) & (cost_new < cost) & jnp.isfinite(cost_new)
        small_step = jnp.max(jnp.abs(delta)) <= atol + rtol * jnp.max(jnp.abs(y))
        tiny = atol + rtol * cost
        # Converged: an accepted step that is small and gains little; or a rejected step that
        # is small and was predicted to gain little (the cost is at its rounding floor, as
        # MINPACK's xtol test); or no decrease predicted at all. μ beyond 1e30 without
        # either: stuck, not converged.
        converged = jnp.where(accept, small_step & (cost - cost_new <= tiny),
                              (small_step & (predicted <= tiny)) | (predicted <= 0))
        stuck = ~accept & (mu > 1e30)
        mu = jnp.where(accept, mu * jnp.maximum(1 / 3, 1 - (2 * rho - 1) ** 3), mu * nu)
        nu = jnp.where(accept, 2.0, 2 * nu)
        pick = lambda a, b: jnp.where(accept, a, b)  # noqa: E731
        return (pick(y_new, y), pick(cost_new, cost), pick(g_new, g), pick(H_new, H), mu, nu,
                k + 1, converged | stuck, converged)

    cost, g, H = normal_equations(y0)
    mu = 1e-3 * jnp.max(jnp.diagonal(H, axis1=1, axis2=2))
    state = (y0, cost, g, H, jnp.maximum(mu, 1e-12), jnp.asarray(2.0, y0.dtype), 0, False,
             False)
    state = jax.lax.while_loop(lambda s: ~s[-2] & (s[-3] < max_steps), step, state)
    return state[0], state[-1], state[-3]


def _dense_residuals(y, args):
    logS, logK = y[:, 0], y[:, 1]
    X, R, R_inf, Rg, prior, ident, logS_fixed, sd = args
    logS = jnp.where(ident, logS, logS_fixed)
    R_model, R_inf_model = model_reflectance(logS, logK, X, Rg.T, sd)
    return (
        (R_model - R.T).ravel(),
        R_inf_model - (R_inf_model if R_inf is None else R_inf),
        prior * jnp.diff(logS),
        prior * jnp.diff(logK),
    )


@functools.partial(jax.jit, static_argnames=("max_steps",))
def _solve_dense(y0, args, max_steps=256):
    """The reference: optimistix's Levenberg–Marquardt on every band at once (a dense
    Jacobian, (m + 1) n × 2n: memory and time grow as n²; for checks at small n)."""
    solver = optx.LevenbergMarquardt(rtol=1e-9, atol=1e-12)
    sol = optx.least_squares(_dense_residuals, solver, y0, args, max_steps=max_steps,
                             throw=False)
    # Only arrays leave the jit (optimistix issue 63: a whole Solution does not vmap).
    return sol.value, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]


@functools.partial(jax.jit, static_argnames=("max_steps",))
def _solve_coupled(y0, args, max_steps=256):
    return _solve_banded(y0, args, max_steps)


@functools.partial(jax.jit, static_argnames=("max_steps",))
def _solve_separable(y0, args, max_steps=256):
    """Without the prior every band is its own 2-parameter problem: `_solve_banded` on one
    band, vmapped over the bands, each with its own damping and its own stopping test."""
    X, R, R_inf, Rg, prior, ident, logS_fixed, sd = args
    one = lambda y, R, Ri, Rg, i, f: _solve_banded(  # noqa: E731
        y[None], (X, R[None], None if Ri is None else Ri[None], Rg[None], prior, i[None],
                  f[None], sd), max_steps)
    y, ok, steps = jax.vmap(one)(y0, R, R_inf, Rg, ident, logS_fixed)
    return y[:, 0], jnp.all(ok), jnp.max(steps)


def fit(m: Measurement, smooth: float = 0.0, noise: float = DEFAULT_NOISE,
        solver: str = "banded", saunderson: tuple[float, float] | None = None) -> KMFit:
    """Fit S(λ), K(λ) to one measurement.

    **Arguments:**

    - `m`: the measurement (`read_measurement`).
    - `smooth`: W of a Gaussian prior that neighbouring bands' log S and log K differ by about
      1/W (standard deviation), weighed against readings of σ = `noise`: the maximum a
      posteriori fit. 0 (default) fits each band on its own; W = 20 allows ~5 % per band.
    - `noise`: σ of one reflectance reading; differences within 3σ count as equal when
      deciding which bands are identifiable.
    - `solver`: `"banded"` (default): per band, vmapped, without the prior; with it, one
      Levenberg–Marquardt whose normal equations are solved block-tridiagonally; O(n) time
      and memory in the number of bands n. `"dense"`: the reference, optimistix's
      Levenberg–Marquardt over all bands at once (O(n²) memory; for checks at small n).
    - `saunderson`: `(k1, k2)` of Saunderson's surface correction (`km.saunderson`): the
      readings include the surface's reflection (SCI), the KM film and the backgrounds under
      it are internal reflectances. The residuals stay in the instrument's readings.

    A contrast card (`m.is_card`) starts from Kubelka's two-background solution
    (`cards.closed_form`) and fits every film over both parts of the card (and R∞ where
    given); its bands' `cards.band_status` says which are identifiable.

    **Returns:** a `KMFit`. **Raises:** `InputError` if no band is identifiable;
    `FitError` if the fit ends with a non-finite S, K or residual.
    """
    if solver not in ("banded", "dense"):
        raise ValueError(f"solver must be 'banded' or 'dense', got {solver!r}")
    if not 0.0 < noise <= MAX_NOISE:  # also refuses nan
        raise ValueError(f"noise must be > 0 and <= {MAX_NOISE:g}, got {noise!r}")
    if not 0.0 <= smooth <= MAX_SMOOTH:
        raise ValueError(f"smooth must be >= 0 and <= {MAX_SMOOTH:g}, got {smooth!r}")
    check_saunderson(m, saunderson)
    status = cards.band_status(m, noise, MIN_RUN) if m.is_card else None
    ident = identifiable(m, noise)
    if not ident.any() and m.is_card:
        raise InputError(
            f"no band where S can be separated from K: the film reads the same over the card's "
            f"black and white parts (within 3√2 x --noise {noise:g}: opaque), or as the card "
            "alone, or inconsistently at every band; measure a thinner film (or a thicker one "
            "if it cannot be seen)", m.path, m.header_line, m.columns[0])
    if not ident.any():
        raise InputError(
            f"no band where S can be separated from K: every thin layer is within 3 x --noise "
            f"{noise:g} of R_inf (opaque) or R_g is; measure a thinner layer or a background "
            "further from R_inf", m.path, m.header_line, m.columns[0],
        )
    S_cf, K_cf = cards.closed_form(m, saunderson) if m.is_card else closed_form(m)
    wl = m.wavelength_nm
    # Start: the closed form where valid; elsewhere log S from valid neighbours, K/S from R∞.
    valid = np.isfinite(S_cf) & ident
    if valid.any():
        logS0 = np.interp(wl, wl[valid], np.log(S_cf[valid]))
    else:
        logS0 = np.full_like(wl, -np.log(np.mean(m.thickness_mm)))
    R_inf0 = (cards.r_inf_start(m, saunderson) if m.is_card
              else cards.internal(m, saunderson)[2])
    ratio = np.asarray(km.ks_from_r_inf(np.clip(R_inf0, 1e-4, 1 - 1e-6)))
    logK0 = np.where(valid, np.log(np.where(valid, K_cf, 1.0)), logS0 + np.log(ratio))
    if solver == "dense":
        solve = _solve_dense
    else:
        solve = _solve_coupled if smooth > 0 else _solve_separable

    with jax.enable_x64(True):
        f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
        Rg = cards.internal(m, saunderson)[1]  # internal, as the model's films are
        sd = None if saunderson is None else tuple(f64(k) for k in saunderson)
        data = (f64(m.thickness_mm), f64(m.R.T), None if m.R_inf is None else f64(m.R_inf),
                f64(Rg.T), f64(smooth * noise), jnp.asarray(ident))
        y, ok, steps = solve(f64(np.stack([logS0, logK0], -1)), (*data, f64(logS0), sd))
        if not ident.all():
            # S where it is not identifiable: from the fitted neighbours (linear in log S
            # between two, the end value held beyond the first or last), K/S kept; then fit
            # again with S held there, so S, K and the fit agree.
            logS, logK = np.asarray(y).T
            logS_fill = np.interp(wl, wl[ident], logS[ident])
            y0 = np.stack([logS_fill, logS_fill + logK - logS], -1)
            y, ok, more = solve(f64(y0), (*data, f64(logS_fill), sd))
            steps = steps + more
        logS, logK = np.asarray(y).T
        R_fit, R_inf_fit = (np.asarray(a) for a in model_reflectance(f64(logS), f64(logK),
                                                                      data[0], data[3].T, sd))
    residual = np.concatenate([(R_fit - m.R).ravel(),
                               [] if m.R_inf is None else R_inf_fit - m.R_inf])
    S, K = np.exp(logS), np.exp(logK)
    bad = np.flatnonzero(~(np.isfinite(S) & np.isfinite(K) & (S > 0) & (K > 0)))
    if bad.size or not np.all(np.isfinite(residual)):
        where = f" at {wl[bad[0]]:g} nm" if bad.size else ""
        raise FitError(f"the fit failed: S, K or the residual is not finite{where}",
                       m.path, m.header_line)
    big = np.flatnonzero(np.maximum(S, K) > MAX_SK_PER_MM)
    if big.size:  # the renderer refuses such a file (float32): not written as if usable
        raise FitError(f"the fit ran S or K past {MAX_SK_PER_MM:g} per mm at {big.size} "
                       f"band(s) (first {wl[big[0]]:g} nm: S {S[big[0]]:.3g}, K "
                       f"{K[big[0]]:.3g}); cosmetics measure about 1e-3 to 1e5: check the "
                       "thickness and the units of the readings", m.path, m.header_line)
    from .coverage import coverage

    return KMFit(
        name=m.name, wavelength_nm=wl, S_per_mm=S, K_per_mm=K,
        identifiable=ident, rmse=float(np.sqrt(np.mean(residual**2))), R_fit=R_fit,
        R_inf_fit=R_inf_fit, S_closed=S_cf, K_closed=K_cf, steps=int(steps),
        converged=bool(ok), smooth=float(smooth), noise=float(noise),
        status=status, saunderson=None if saunderson is None else tuple(
            float(k) for k in saunderson), thickness_known=m.thickness_known,
        coverage=coverage(m, S, K, saunderson),
    )


def check_saunderson(m: Measurement, saunderson) -> None:
    """`InputError` unless `saunderson` is None or `(k1, k2)` with 0 <= k1 < 1, 0 <= k2 < 1,
    and every reading of `m` at least k1 (a reading below the surface's own reflection has
    no internal reflectance: specular-excluded readings want k1 = 0)."""
    if saunderson is None:
        return
    k1, k2 = saunderson
    if not (0 <= k1 < 1 and 0 <= k2 < 1):
        raise InputError(f"--saunderson K1,K2 must each lie in [0, 1), got {k1:g},{k2:g}",
                         m.path)
    readings = [(c, r) for c, r in zip(m.columns, m.R, strict=True)]
    readings += [("R_g_black" if m.is_card else "R_g", m.R_g)]
    readings += [("R_g_white", m.R_g_white)] if m.is_card else []
    readings += [] if m.R_inf is None else [("R_inf", m.R_inf)]
    for column, values in readings:
        low = np.flatnonzero(values < k1)
        if low.size:
            i = low[0]
            raise InputError(f"reads {values[i]:g} at {m.wavelength_nm[i]:g} nm, below "
                             f"--saunderson K1 = {k1:g} (the surface's own reflection): "
                             "specular-excluded (SCE) readings want K1 = 0", m.path,
                             m.header_line, column)
