"""The biophysical skin model (`jaxskin.biophysical`) fitted to measured reflectance spectra.

`jaxskin fit-skin SPECTRA.csv -o DIR`: each spectrum (a column of a wide CSV, or a subject's
mean in the NIST file) gets the six parameters of `biophysical.Skin` that reproduce it
best in the least-squares sense over 400–700 nm (the measured points there; the model is
evaluated at the measured wavelengths, nothing is resampled).

- The fitted range is 400–700 nm, what every accepted spectrum covers, so a fit does not
  depend on how far an instrument reaches beyond it; it is also where the colour is. On
  the 100 NIST forearms it gives a closer colour over the whole 380–780 nm than fitting
  380–780 did (ΔE2000 median 0.59 against 0.67, max 1.37 against 1.76, both measured
  against every reading in 380–780: `benchmarks/RESULTS.md`): outside it the model's
  misfit (420–450 nm and the short-wave end) pulled the fit away from the visible middle.

- Instruments: any sampling (1–10 nm steps are usual) and any range that covers 400–700 nm.
  Each point weighs its share of the spectrum (half the distance to its neighbours, over
  the 3 nm of the NIST file's step), so the fit minimises ∫ (R_model − R)² dλ whatever the
  sampling: a 1 nm instrument's spectrum does not weigh 3 × a 3 nm one's against the weak
  prior, nor does a denser stretch of a spectrum outweigh the rest. A missing reading
  (NaN) is left out of its spectrum alone.
- d/8 sphere instruments report the specular component included (SCI) or excluded (SCE,
  the default): with `specular=True` the model adds the surface's own reflection k1
  (`biophysical.reflectance(..., specular=True)`), which an SCI reading holds.

- Bounds by a transform: each parameter is `lo + (hi − lo) σ(z)` of an unbounded z
  (`biophysical.RANGES`), in log space for the ones spanning decades (melanin,
  haemoglobin, epidermis thickness, scattering), so Levenberg–Marquardt (optimistix,
  float64) works on z without constraints.
- Several starts per spectrum (the model's default, then random z), all spectra × starts
  vmapped in one compiled program per chunk of spectra; the lowest finite loss wins, so a
  start that diverges or stalls never sinks a fit.
- Figures of merit per spectrum: the RMS reflectance error over the fitted points and
  ΔE2000 between measured and fitted spectra under D65 (CIE 1931 2°, colour-science:
  both spectra at every reading in 380–780 nm, resampled the same way to 5 nm, XYZ by
  ASTM E308 weights, CIELAB, CIEDE2000).
"""

from __future__ import annotations

import dataclasses
import functools
import math

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from jaxskin import biophysical as bp
from jaxskin.formats import haemoglobin_table
from jaxskin.io import FitError, InputError
from jaxskin.spectral import Grid

from ._skin_files import LOG_PARAMS, specular_word, write_csv, write_report

__all__ = ["FIT_RANGE", "LOG_PARAMS", "NEEDED", "SHOWN", "SkinFit", "coverage", "delta_e2000",
           "fit", "from_z", "point_weights", "specular_word", "to_z", "write_csv",
           "write_report"]

NEEDED = (400.0, 700.0)  # nm: a spectrum must cover at least this
FIT_RANGE = NEEDED  # the points the fit uses: the same stretch of every accepted spectrum
SHOWN = (380.0, 780.0)  # the points the colour (dE2000) and the report's plots use
CHUNK = 10  # spectra per compiled solve (the progress bar's step)
PRIOR = 1e-3  # weight of the prior on z (see `_residuals`)
STEP_NM = 3.0  # a point standing for this many nm weighs 1 (the NIST file's step: its fits
# weigh each point as before)


@dataclasses.dataclass(frozen=True)
class SkinFit:
    """Per spectrum `(m,)`: `params` (name → values), `rms`, `dE2000`, `converged`, `steps`,
    `sd` (name → the linearised standard deviation of each parameter, 0 when fixed) and
    `corr_melanin_epidermis` (their correlation: the spectra fix melanin × thickness better
    than each); `wavelengths (n,)` the readings' in `SHOWN` (380–780 nm; the fit used those
    in `FIT_RANGE`), `measured` (NaN where a spectrum has no reading), `fitted (m, n)`
    there; `specular`: whether the model included the surface's
    reflection (an SCI instrument's spectra)."""

    names: list[str]
    wavelengths: np.ndarray
    measured: np.ndarray
    fitted: np.ndarray
    params: dict[str, np.ndarray]
    rms: np.ndarray
    dE2000: np.ndarray
    converged: np.ndarray
    steps: np.ndarray
    sd: dict[str, np.ndarray]
    corr_melanin_epidermis: np.ndarray
    specular: bool = False


def _bounds(name):
    lo, hi = bp.RANGES[name]
    return (math.log(lo), math.log(hi)) if name in LOG_PARAMS else (lo, hi)


def from_z(z) -> bp.Skin:
    """The parameters of unbounded `z (..., 6)` (order `biophysical.PARAMS`)."""
    out = []
    for i, name in enumerate(bp.PARAMS):
        lo, hi = _bounds(name)
        v = lo + (hi - lo) * jax.nn.sigmoid(z[..., i])
        out.append(jnp.exp(v) if name in LOG_PARAMS else v)
    return bp.Skin(*out)


def to_z(skin: bp.Skin) -> np.ndarray:
    """The inverse of `from_z` (host float64); values at the bounds map to ±13."""
    out = []
    for name, v in zip(bp.PARAMS, skin, strict=True):
        lo, hi = _bounds(name)
        v = np.log(v) if name in LOG_PARAMS else np.asarray(v, np.float64)
        t = np.clip((v - lo) / (hi - lo), 2e-6, 1 - 2e-6)
        out.append(np.log(t / (1 - t)))
    return np.stack(np.broadcast_arrays(*out), axis=-1)


def delta_e2000(wavelengths, measured, fitted) -> np.ndarray:
    """CIEDE2000 between spectra `measured` and `fitted (..., n)` at `wavelengths (n,)`
    under D65 (CIE 1931 2°): both resampled linearly to 380–780 nm at 5 nm (ends held),
    from the points where `measured` has a reading (not NaN), XYZ by colour-science's
    ASTM E308 weights, CIELAB with the illuminant's white."""
    import colour

    grid = Grid(5, illuminant="D65")
    W = grid.xyz_matrix
    white_xy = colour.XYZ_to_xy(W.sum(axis=0))
    M = np.asarray(measured, np.float64).reshape(-1, np.shape(measured)[-1])
    F = np.broadcast_to(np.asarray(fitted, np.float64), np.shape(measured)).reshape(M.shape)
    wl = np.asarray(wavelengths, np.float64)

    def lab(R):
        on = np.stack([np.interp(grid.wavelengths, wl[np.isfinite(m)], r[np.isfinite(m)])
                       for m, r in zip(M, R, strict=True)])
        return colour.XYZ_to_Lab(on @ W, white_xy)

    de = colour.delta_E(lab(M), lab(F), method="CIE 2000")
    return np.asarray(de).reshape(np.shape(measured)[:-1])


def coverage(wavelengths, R) -> np.ndarray:
    """`(m, 2)`: each spectrum's first and last wavelength with a reading (not NaN) in
    `R (m, n)` at `wavelengths (n,)`; NaN for a spectrum without any."""
    wl = np.asarray(wavelengths, np.float64)
    ok = np.isfinite(np.atleast_2d(R))
    first = np.where(ok.any(1), wl[np.argmax(ok, axis=1)], np.nan)
    last = np.where(ok.any(1), wl[len(wl) - 1 - np.argmax(ok[:, ::-1], axis=1)], np.nan)
    return np.stack([first, last], axis=-1)


def point_weights(wavelengths, mask) -> np.ndarray:
    """`(m, n)` least-squares weights w² of the points of each spectrum (`mask (m, n)`:
    where it has a reading): the trapezoid rule's share of its own points, half the distance
    to the neighbours (at the ends, half the step), over `STEP_NM`; 0 where no reading. So
    Σ w² r² ≈ ∫ r² dλ / 3 nm whatever the sampling."""
    wl = np.asarray(wavelengths, np.float64)
    out = np.zeros(np.shape(mask))
    for k, m in enumerate(np.atleast_2d(mask)):
        x = wl[m]
        if x.size > 1:
            edges = np.r_[x[0], (x[1:] + x[:-1]) / 2, x[-1]]
            out[k, m] = np.diff(edges) / STEP_NM
    return out


def _residuals(z, args):
    c, R, w, z_all, free, specular = args
    z = z_all.at[jnp.asarray(free)].set(z)
    # The data (each point weighted by its share of the spectrum, `point_weights`), then a
    # weak prior pulling z towards 0 (weight PRIOR): without it a parameter that wants to
    # sit on its bound drives z to ±∞ and LM never converges; with it z stays near ±10
    # there, where the bound is reached to 1e-4 of the range.
    return jnp.concatenate([w * (bp.reflectance(c, from_z(z), specular) - R), PRIOR * z])


@functools.partial(jax.jit, static_argnames=("free", "max_steps", "specular"))
def _solve(z0, R, w, c, free, specular=False, max_steps=300):
    """LM for every (spectrum, start): `z0 (m, S, 6)` (the fixed parameters' entries are
    their values), `R (m, n)` (0 where no reading), `w (m, n)` the square roots of the
    points' weights (0 where no reading); `free`: the indices of the parameters fitted;
    `specular`: the model includes the surface's reflection (SCI)."""
    # The damped step by Cholesky of the 6×6 normal equations (as fitting.brdf): the same
    # fits as the default QR, 20 % less to compile and run here.
    solver = optx.LevenbergMarquardt(rtol=1e-6, atol=1e-8,
                                     linear_solver=lx.Normal(lx.Cholesky()))

    def one(z_all, R_k, w_k):
        args = (c, R_k, w_k, z_all, free, specular)
        sol = optx.least_squares(_residuals, solver, z_all[jnp.asarray(free)], args,
                                 max_steps=max_steps, throw=False)
        r = _residuals(sol.value, args)[:R_k.shape[-1]]  # the data's share of the loss
        return z_all.at[jnp.asarray(free)].set(sol.value), jnp.sum(r * r), \
            sol.result == optx.RESULTS.successful, sol.stats["num_steps"]

    return jax.vmap(jax.vmap(one, in_axes=(0, None, None)), in_axes=(0, 0, 0))(z0, R, w)


def _starts(rng, m: int, starts: int) -> np.ndarray:
    """`(m, starts, 6)`: the default skin first, then random z ~ N(0, 1.5²)."""
    z = rng.normal(0.0, 1.5, (m, starts, len(bp.PARAMS)))
    z[:, 0] = to_z(bp.DEFAULT)
    return z


def solve_chunk(unit) -> list[np.ndarray]:
    """One chunk of `fit`'s work, `(z0 (CHUNK, S, 6), R (CHUNK, n), w (CHUNK, n),
    wavelengths (n,), free, specular)` → `[z, loss, converged, steps]` as NumPy arrays, in
    float64; here or on a worker."""
    z0, R, w, wl, free, specular = unit
    with jax.enable_x64(True):
        c = bp.Chromophores(*(jnp.asarray(a, jnp.float64)
                              for a in bp.chromophores(wl, haemoglobin_table())))
        return [np.asarray(a) for a in _solve(jnp.asarray(z0), jnp.asarray(R), jnp.asarray(w),
                                              c, free, specular)]


def fit(names, wavelengths, R, starts: int = 4, seed: int = 0, fixed=None, progress=None,
        path=None, map_units=None, specular: bool = False) -> SkinFit:
    """Fit the biophysical model to each spectrum.

    **Arguments:**

    - `names`: one per spectrum; `wavelengths (n,)` nm, increasing; `R (m, n)` reflectance
      (0–1), NaN where a spectrum has no reading.
    - `starts`: starts per spectrum (the default skin and random ones; deterministic for
      a `seed`).
    - `fixed`: `{name: value}` of parameters held at a value instead of fitted.
    - `progress`: called with the number of spectra done after each chunk (a progress bar).
    - `path`: the input file, for messages.
    - `map_units`: how the chunks' solves run, `map_units(solve_chunk, units)` → their
      results in order (`jaxskin.cluster.Pool.mapper` runs them on a cluster; `progress`
      is then unused); default here, one after the other.
    - `specular`: the spectra include the specular component (an SCI instrument): the
      model adds the surface's reflection k1.

    **Returns:** a `SkinFit`. **Raises:** `InputError` if a spectrum does not cover
    400–700 nm (the caller drops those first: `coverage`) or has too few points;
    `FitError` if every start of some spectrum failed.
    """
    wavelengths = np.asarray(wavelengths, np.float64)
    R = np.atleast_2d(np.asarray(R, np.float64))
    span = coverage(wavelengths, R)
    short = ~((span[:, 0] <= NEEDED[0]) & (span[:, 1] >= NEEDED[1]))  # NaN: short too
    if short.any():
        k = int(np.argmax(short))
        raise InputError(f"spectrum '{names[k]}' covers {_span_text(span[k])}; the fit needs "
                         f"at least {NEEDED[0]:g}-{NEEDED[1]:g} nm", path)
    table = haemoglobin_table()
    shown = ((wavelengths >= max(SHOWN[0], table[0][0]))
             & (wavelengths <= min(SHOWN[1], table[0][-1])))
    wl_all, R_all = wavelengths[shown], R[:, shown]
    use = (wl_all >= FIT_RANGE[0]) & (wl_all <= FIT_RANGE[1])
    wl, Rm = wl_all[use], R_all[:, use]
    mask = np.isfinite(Rm)
    few = mask.sum(axis=1) < 2 * len(bp.PARAMS)
    if few.any():
        k = int(np.argmax(few))
        raise InputError(f"spectrum '{names[k]}' has only {int(mask[k].sum())} readings in "
                         f"{FIT_RANGE[0]:g}-{FIT_RANGE[1]:g} nm; the fit needs at least "
                         f"{2 * len(bp.PARAMS)}", path)
    w = np.sqrt(point_weights(wl, mask))
    Rz = np.where(mask, Rm, 0.0)
    m = len(Rm)
    z0 = _starts(np.random.default_rng(seed), m, starts)
    fixed = dict(fixed or {})
    for name, value in fixed.items():
        z0[..., bp.PARAMS.index(name)] = to_z(bp.DEFAULT._replace(**{name: value}))[
            bp.PARAMS.index(name)]
    free = tuple(i for i, name in enumerate(bp.PARAMS) if name not in fixed)
    pad, chunk = (-m) % CHUNK, CHUNK  # one shape: one compiled program for any m
    z0p, Rp, wp = (np.concatenate([a, np.repeat(a[-1:], pad, 0)]) for a in (z0, Rz, w))
    units = [(z0p[i:i + chunk], Rp[i:i + chunk], wp[i:i + chunk], wl, free, bool(specular))
             for i in range(0, m + pad, chunk)]

    def here(fn, units):
        for i, unit in zip(range(0, m + pad, chunk), units, strict=True):
            yield fn(unit)
            if progress is not None:
                progress(min(chunk, m - i))

    out = list((map_units or here)(solve_chunk, units))
    with jax.enable_x64(True):
        c = bp.Chromophores(*(jnp.asarray(a, jnp.float64) for a in bp.chromophores(wl, table)))
        z, loss, ok, steps = (np.concatenate(parts)[:m] for parts in zip(*out, strict=True))
        loss = np.where(np.isfinite(loss) & np.all(np.isfinite(z), axis=-1), loss, np.inf)
        failed = ~np.isfinite(loss).any(axis=1)
        if failed.any():
            raise FitError(f"every start failed for spectrum '{names[int(np.argmax(failed))]}';"
                           " try more --starts", path)
        best = np.argmin(loss, axis=1)
        zb = z[np.arange(m), best]
        skin = from_z(jnp.asarray(zb))
        fitted = np.asarray(bp.reflectance(c, skin, bool(specular)))
        cov = np.asarray(_covariance(c, jnp.stack(skin, axis=-1), jnp.asarray(Rz),
                                     jnp.asarray(w), free, bool(specular)))
        c_all = bp.Chromophores(*(jnp.asarray(a, jnp.float64)
                                  for a in bp.chromophores(wl_all, table)))
        fitted_all = np.asarray(bp.reflectance(c_all, skin, bool(specular)))
    params = {name: np.asarray(v) for name, v in zip(bp.PARAMS, skin, strict=True)}
    rms = np.sqrt(np.sum(np.where(mask, fitted - Rz, 0.0) ** 2, axis=-1) / mask.sum(axis=-1))
    dE = delta_e2000(wl_all, R_all, fitted_all)  # the colour over all readings in 380-780
    sd = {name: np.sqrt(np.maximum(cov[:, i, i], 0.0)) for i, name in enumerate(bp.PARAMS)}
    i, j = bp.PARAMS.index("melanin"), bp.PARAMS.index("epidermis_mm")
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = cov[:, i, j] / (sd["melanin"] * sd["epidermis_mm"])
    return SkinFit(list(names), wl_all, R_all, fitted_all, params, rms, dE,
                   ok[np.arange(m), best],
                   steps[np.arange(m), best], sd, corr, bool(specular))


def _span_text(span) -> str:
    """A spectrum's `coverage` row as words."""
    return "no wavelength" if not np.isfinite(span[0]) else f"{span[0]:g}-{span[1]:g} nm"


@functools.partial(jax.jit, static_argnames=("free", "specular"))
def _covariance(c, p, R, w, free, specular=False):
    """The linearised covariance of the fitted parameters `p (m, 6)` (in their own units)
    over the free ones, for the weighted least squares `fit` solves (weights W = w²,
    0 where no reading): the sandwich σ² A⁺ (Jᵀ W² J) A⁺ with A = Jᵀ W J, J = ∂R/∂p at the
    fit, σ² = Σ r² / (n − k) over the n readings (the residuals as noise, the same at every
    point: model error counts as noise too); with equal weights it is σ² (JᵀJ)⁻¹. 0 for
    the fixed ones."""
    k = len(free)

    def one(p_k, R_k, w_k):
        def model(q):
            return bp.reflectance(c, bp.Skin(*p_k.at[jnp.asarray(free)].set(q)), specular)

        q = p_k[jnp.asarray(free)]
        J = jax.jacfwd(model)(q)
        W = w_k * w_k
        on = W > 0
        r = jnp.where(on, model(q) - R_k, 0.0)
        var = jnp.sum(r * r) / jnp.maximum(jnp.sum(on) - k, 1)
        A = jnp.linalg.pinv(J.T @ (W[:, None] * J), hermitian=True)
        inner = A @ (J.T @ ((W * W)[:, None] * J)) @ A
        out = jnp.zeros((len(bp.PARAMS), len(bp.PARAMS)), p_k.dtype)
        idx = jnp.asarray(free)
        return out.at[idx[:, None], idx[None, :]].set(var * inner)

    return jax.vmap(one)(p, R, w)


def fit_warnings(result: SkinFit, fixed=()) -> list[str]:
    """Lines for the spectra whose fit is not to be trusted as it is: those that did not
    converge, and a parameter that ends at an end of the literature's range it is held to
    (within 0.5 % of the range, in the fitted log scale: melanin, haemoglobin, epidermis,
    scattering; the fractions eumelanin and oxygenation end at 0 or 1 naturally), where the
    best fit may lie outside the model's range; at most five names each."""
    def names(mask, values=None):
        picked = [n if values is None else f"{n} = {v:.3g}"
                  for n, m, v in zip(result.names, mask,
                                     values if values is not None else mask, strict=True) if m]
        more = f" and {len(picked) - 5} more" if len(picked) > 5 else ""
        return ", ".join(picked[:5]) + more

    out = []
    stuck = ~np.asarray(result.converged, bool)
    if stuck.any():
        out.append(f"{int(stuck.sum())} of {len(stuck)} spectra did not converge "
                   f"({names(stuck)}): their rows say converged=false; more --starts may help")
    for p in LOG_PARAMS:
        if p in dict(fixed) or p not in result.params:
            continue
        lo, hi = _bounds(p)
        z = np.log(np.maximum(np.asarray(result.params[p], np.float64), 1e-300))
        tol = 0.005 * (hi - lo)
        for end, at in (("lower", z <= lo + tol), ("upper", z >= hi - tol)):
            if at.any():
                bound = bp.RANGES[p][0 if end == "lower" else 1]
                k = int(at.sum())
                out.append(f"{p} ends at the {end} end of its range ({bound:g}, within "
                           f"0.5 % of the range's log) for {k} "
                           f"{'spectrum' if k == 1 else 'spectra'} "
                           f"({names(at, result.params[p])}): the best fit may lie outside "
                           "the model's range; check their rms and dE2000")
    return out
