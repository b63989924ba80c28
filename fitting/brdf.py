"""Lafortune lobes fitted to BRDF samples (Lafortune et al. 1997; Bando 2001 §4.2).

Input CSV: `theta_in_deg, phi_in_deg, theta_out_deg, phi_out_deg, R, G, B` (angles in the
local frame, z = normal) or unit vectors `wi_x, wi_y, wi_z, wo_x, wo_y, wo_z` in place of
the angles; BRDF values in 1/sr; an optional `weight` column.

The fit: per channel, ρd and N lobes (Cxy, Cz, n) by Levenberg–Marquardt (optimistix,
float64) on residuals weighted by cos θ_in (what the value contributes to reflected
radiance) and the sample weights, normalised by the data's own size. n = exp(·) and
ρd = exp(·) stay positive by construction. Several starts per channel — half built from
typical lobe shapes, half random — run at once (vmapped over channels × starts); the lowest
finite loss wins, so a start that fails —
diverges, gives NaN, stops unconverged — never sinks the fit.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from pathlib import Path

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx

from jaxskin.formats import decimal_comma_note, is_measurement_table, read_table
from jaxskin.io import FitError, InputError, atomic_write
from jaxskin.shading import lafortune

__all__ = ["BRDFFit", "BRDFSamples", "check_samples", "distinct_pairs", "fit", "fit_warnings",
           "read_samples", "write_report"]

ANGLES = ("theta_in_deg", "phi_in_deg", "theta_out_deg", "phi_out_deg")
VECTORS = ("wi_x", "wi_y", "wi_z", "wo_x", "wo_y", "wo_z")
RGB = ("R", "G", "B")
# Beyond these a number is a typo or an overflow, not a measurement: a mirror-like lobe
# peaks at ~1e4 1/sr, and weights are relative.
MAX_BRDF = 1e6
MAX_WEIGHT = 1e6
_EXPECTED = ", ".join(ANGLES + RGB) + " (or " + ", ".join(VECTORS) + "), optional weight"


@dataclasses.dataclass(frozen=True)
class BRDFSamples:
    """Directions `wi`, `wo` `(m, 3)` (unit, local frame), values `f (m, 3)`, `weight (m,)`."""

    path: object
    wi: np.ndarray
    wo: np.ndarray
    f: np.ndarray
    weight: np.ndarray
    notes: tuple[str, ...] = ()  # what the reader noticed (decimal commas), for the user


def _direction(theta_deg, phi_deg):
    t, p = np.radians(theta_deg), np.radians(phi_deg)
    return np.stack([np.sin(t) * np.cos(p), np.sin(t) * np.sin(p), np.cos(t)], axis=-1)


def _nearest(cell: str) -> str:
    """"(did you mean 'theta_in_deg'?)" for a column name close to one of the format's."""
    import difflib

    close = difflib.get_close_matches(cell, (*ANGLES, *VECTORS, *RGB, "weight"), n=1,
                                      cutoff=0.6)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _misspelt_header(path: Path):
    """`(line, cell)` of the first header cell that is not a column name, where the first
    row that is not a comment names columns (most of its cells are the format's names, or
    close to them) but no row was taken as the header; else None."""
    from jaxskin.formats import text_rows

    names = (*ANGLES, *VECTORS, *RGB, "weight")
    for number, cells in text_rows(path):
        near = [c for c in cells if c in names or _nearest(c)]
        unknown = [c for c in cells if c not in names]
        if len(cells) >= 4 and len(near) >= len(cells) - 1 and unknown:
            return number, unknown[0]
        return None
    return None


def read_samples(path) -> BRDFSamples:
    """Read and check a BRDF sample CSV; `InputError` names the file, line and column."""
    try:
        t = read_table(path, lambda cell: cell in (*ANGLES, *VECTORS), _EXPECTED)
    except InputError as e:
        if Path(path).is_file() and is_measurement_table(Path(path)):
            raise InputError("a table of spectra (a wavelength column), not BRDF samples: a "
                             "cosmetic's measurement goes to 'jaxskin calibrate', skin "
                             "spectra to 'jaxskin fit-skin'", path) from None
        misspelt = _misspelt_header(Path(path)) if "no header row" in str(e) else None
        if misspelt is not None:  # a header with a typo: named, not "no header row"
            line, cell = misspelt
            raise InputError(f"unknown column{_nearest(cell)}; expected {_EXPECTED}", path,
                             line, cell) from None
        raise
    names = set(t.header)
    unknown = [c for c in t.header if c not in {*ANGLES, *VECTORS, *RGB, "weight"}]
    if unknown:
        raise t.error(f"unknown column{_nearest(unknown[0])}; expected {_EXPECTED}",
                      column=unknown[0])
    for c in RGB:
        if c not in names:
            raise t.error(f"missing column {c}; expected {_EXPECTED}")
    has_angles, has_vectors = names & set(ANGLES), names & set(VECTORS)
    if has_angles and has_vectors:
        raise t.error("give the directions as angles or as vectors, not both")
    if has_angles or not has_vectors:
        for c in ANGLES:
            if c not in names:
                raise t.error(f"missing column {c}; expected {_EXPECTED}")
        for c in ("theta_in_deg", "theta_out_deg"):
            bad = np.flatnonzero((t.column(c) < 0) | (t.column(c) > 90))
            if bad.size:
                raise t.error(f"polar angle must be in [0, 90] degrees, got "
                              f"{t.column(c)[bad[0]]:g}", bad[0], c)
        polar = np.concatenate([t.column("theta_in_deg"), t.column("theta_out_deg")])
        if len(t.data) >= 8 and 0 < polar.max() <= math.pi / 2 + 1e-6:
            raise t.error(f"every polar angle is at most {polar.max():.4g}: radians? The "
                          "columns are in degrees (0-90); convert them, or give unit vectors "
                          "(wi_x, ..., wo_z)", column="theta_in_deg")
        for c in ("phi_in_deg", "phi_out_deg"):
            bad = np.flatnonzero(np.abs(t.column(c)) > 360)
            if bad.size:
                raise t.error(f"azimuth must be in [-360, 360] degrees, got "
                              f"{t.column(c)[bad[0]]:g}", bad[0], c)
        wi = _direction(t.column("theta_in_deg"), t.column("phi_in_deg"))
        wo = _direction(t.column("theta_out_deg"), t.column("phi_out_deg"))
    else:
        for c in VECTORS:
            if c not in names:
                raise t.error(f"missing column {c}; expected {_EXPECTED}")
        vectors = []
        for prefix in ("wi", "wo"):
            v = np.stack([t.column(f"{prefix}_{a}") for a in "xyz"], axis=-1)
            length = np.linalg.norm(v, axis=-1)
            bad = np.flatnonzero(np.abs(length - 1) > 1e-3)
            if bad.size:
                raise t.error(f"direction must be a unit vector, has length {length[bad[0]]:.4g}",
                              bad[0], f"{prefix}_x")
            bad = np.flatnonzero(v[:, 2] < 0)
            if bad.size:
                raise t.error("direction points below the surface (z < 0)", bad[0],
                              f"{prefix}_z")
            vectors.append(v / length[:, None])
        wi, wo = vectors
    f = np.stack([t.column(c) for c in RGB], axis=-1)
    for k, c in enumerate(RGB):
        bad = np.flatnonzero((f[:, k] < 0) | (f[:, k] > MAX_BRDF))
        if bad.size:
            raise t.error(f"BRDF values must be in [0, {MAX_BRDF:g}] 1/sr, got "
                          f"{f[bad[0], k]:g}", bad[0], c)
        if not np.any(f[:, k] > 0):
            raise t.error("every value is 0: there is nothing to fit", column=c)
    weight = t.column("weight") if "weight" in names else np.ones(len(f))
    bad = np.flatnonzero((weight < 0) | (weight > MAX_WEIGHT))
    if bad.size:
        raise t.error(f"weights must be in [0, {MAX_WEIGHT:g}], got {weight[bad[0]]:g}",
                      bad[0], "weight")
    if not np.any(weight > 0):
        raise t.error("every weight is 0", column="weight")
    notes = (f"{path}: {decimal_comma_note(t.decimal_comma)}",) if t.decimal_comma else ()
    return BRDFSamples(t.path, wi, wo, f, weight, notes)


@dataclasses.dataclass(frozen=True)
class BRDFFit:
    """The fitted lobes (float64), relative RMS error per channel, and the starts' record."""

    params: lafortune.Lafortune
    rel_rms: np.ndarray  # (3,)
    losses: np.ndarray  # (3, starts): final loss of every start, inf where it failed
    best: np.ndarray  # (3,): the winning start per channel
    converged: np.ndarray  # (3, starts)
    steps: np.ndarray  # (3, starts)

    def stats(self) -> dict:
        """The fit's record for the JSON file: relative RMS error per channel, starts, failed
        starts, the best start and its steps."""
        return {
            "relative_rms_error": [float(e) for e in self.rel_rms],
            "starts": int(self.losses.shape[1]),
            "failed_starts": [int(np.sum(~np.isfinite(row))) for row in self.losses],
            "best_start": [int(b) for b in self.best],
            "steps_of_best": [int(self.steps[c, b]) for c, b in enumerate(self.best)],
        }


def _unpack(theta, lobes):
    """theta (1 + 3 lobes,) → one channel's Lafortune (channel axis of size 1)."""
    log_rho, Cxy, Cz, log_n = theta[0], theta[1:1 + lobes], theta[1 + lobes:1 + 2 * lobes], \
        theta[1 + 2 * lobes:]
    return lafortune.Lafortune(jnp.exp(log_rho)[None], Cxy[:, None], Cz[:, None],
                               jnp.exp(log_n)[:, None])


def _residuals(theta, args):
    wi, wo, f, w_cos, scale = args
    lobes = (theta.shape[0] - 1) // 3
    model = lafortune.brdf(_unpack(theta, lobes), wi, wo)[..., 0]
    return w_cos * (model - f) / scale


MAX_STEPS = 200  # Levenberg–Marquardt steps a start may take
# A fitted diffuse albedo above this is warned about: above 1 is unphysical, but a fit to
# few or noisy samples trades a little of it with the lobes (1.01 in a cluster test's fit);
# values in 0-255 or percent give tens to hundreds.
ALBEDO_WARN = 1.5


@functools.partial(jax.jit, static_argnames=("max_steps",))
def _solve_all(theta0, wi, wo, f, w_cos, scale, max_steps=MAX_STEPS):
    """LM for every (channel, start) at once: theta0 (C, S, P), f (C, m), scale (C,).

    The damped step solves the small normal equations (Cholesky) rather than a QR of the
    tall Jacobian: 1.6x faster here, and float64 keeps it accurate."""
    solver = optx.LevenbergMarquardt(rtol=1e-8, atol=1e-10,
                                     linear_solver=lx.Normal(lx.Cholesky()))

    def one(theta, f_c, scale_c):
        sol = optx.least_squares(_residuals, solver, theta, (wi, wo, f_c, w_cos, scale_c),
                                 max_steps=max_steps, throw=False)
        r = _residuals(sol.value, (wi, wo, f_c, w_cos, scale_c))
        loss = jnp.sum(r * r)
        # Only arrays leave the vmap (optimistix issue 63).
        return sol.value, loss, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]

    per_start = jax.vmap(one, in_axes=(0, None, None))
    return jax.vmap(per_start, in_axes=(0, 0, 0))(theta0, f, scale)


def solve_channel(unit) -> tuple[np.ndarray, ...]:
    """One channel's starts, a unit of `fit`'s work: `(theta0 (S, P), wi, wo, f (m,),
    w_cos, scale)` → `(theta (S, P), loss (S,), converged (S,), steps (S,))`, in float64.
    Channels solve apart (each stops when its own starts converge), here or on a worker."""
    theta0, wi, wo, f_c, w_cos, scale_c = unit
    with jax.enable_x64(True):
        f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
        out = _solve_all(f64(theta0)[None], f64(wi), f64(wo), f64(f_c)[None], f64(w_cos),
                         f64(scale_c)[None])
        return tuple(np.asarray(a)[0] for a in out)


def _map_here(fn, units):
    return (fn(u) for u in units)


# Lobe shapes the structured starts are built from (Cxy, Cz, n range): a sharp lobe about
# the mirror direction, a broad forward-scattering one, a broad retro-reflecting one.
_TEMPLATES = ((-1.0, 0.9, (20.0, 300.0)), (-1.1, -1.1, (2.0, 10.0)), (0.6, 0.6, (1.0, 8.0)))


def _starts(rng, starts, lobes, f_c):
    """Half structured (lobe i starts as template i mod 3, jittered), half random starts.

    Measured on the skin preset with 2 % noise: random starts alone left the green channel
    in a local minimum (12 % held-out error) that the structured ones avoid (0.5 %).
    """
    rho = math.log(max(math.pi * float(np.percentile(f_c, 20)), 1e-3))
    out = np.empty((starts, 1 + 3 * lobes))
    for s in range(starts):
        if s % 2 == 0:
            kinds = [_TEMPLATES[i % 3] for i in range(lobes)]
            Cxy = np.array([k[0] for k in kinds]) + rng.normal(0, 0.15, lobes)
            Cz = np.array([k[1] for k in kinds]) + rng.normal(0, 0.15, lobes)
            log_n = np.array([rng.uniform(np.log(k[2][0]), np.log(k[2][1])) for k in kinds])
        else:
            Cxy = rng.uniform(-1.3, 1.3, lobes)
            Cz = rng.uniform(-0.5, 1.2, lobes)
            log_n = rng.uniform(np.log(1.0), np.log(300.0), lobes)
        out[s] = np.concatenate([[rho], Cxy, Cz, log_n])
    return out


def check_samples(samples, lobes: int) -> None:
    """`InputError` when `samples` cannot determine the `1 + 3 lobes` parameters of a
    channel: fewer weighted samples than that, or fewer distinct direction pairs as the
    lobes see them (`distinct_pairs`: 50 copies of one pair fitted to 0.00 % with
    arbitrary lobes). Checked before any work."""
    params_per_channel = 1 + 3 * lobes
    weighted = np.count_nonzero(samples.weight)
    if weighted < params_per_channel:
        raise InputError(f"{weighted} weighted samples cannot determine "
                         f"{params_per_channel} parameters per channel ({lobes} lobes); give "
                         "more samples or ask for fewer --lobes", samples.path)
    pairs = distinct_pairs(samples)
    if pairs < params_per_channel:
        raise InputError(f"{weighted} weighted samples but {pairs} distinct direction "
                         f"pair{'s' * (pairs != 1)} cannot determine {params_per_channel} "
                         f"parameters per channel ({lobes} lobes): the lobes see a pair "
                         "through wi_x wo_x + wi_y wo_y and wi_z wo_z only, so repeated "
                         "pairs, pairs turned about the normal and in/out swapped count "
                         "once; give samples at more directions or ask for fewer --lobes",
                         samples.path)


def distinct_pairs(samples) -> int:
    """How many weighted samples differ as the Lafortune model sees them: by
    `(wi_x wo_x + wi_y wo_y, wi_z wo_z)` (the isotropic model, `lafortune.brdf`), each
    rounded to 1e-9 (an angle's last printed digit moves them by far more)."""
    w = samples.weight > 0
    wi, wo = samples.wi[w], samples.wo[w]
    seen = np.stack([wi[:, 0] * wo[:, 0] + wi[:, 1] * wo[:, 1], wi[:, 2] * wo[:, 2]], axis=1)
    return len(np.unique(np.round(seen, 9) + 0.0, axis=0))  # + 0.0: -0.0 as 0.0


def fit(samples: BRDFSamples, lobes: int = 3, starts: int = 8, seed: int = 0,
        initial: lafortune.Lafortune | None = None, map_units=None) -> BRDFFit:
    """Fit ρd and `lobes` Lafortune lobes per channel.

    **Arguments:**

    - `samples`: from `read_samples`.
    - `lobes`: lobes per channel (default 3).
    - `starts`: random starts per channel (deterministic for a given `seed`).
    - `initial`: an optional guess, tried as one more start (e.g. `lafortune.skin()`).
    - `map_units`: how the three channels' solves run, `map_units(solve_channel, units)` →
      their results in order (`jaxskin.cluster.Pool.map` runs them on a cluster); default
      here, one after the other.

    **Returns:** a `BRDFFit`.
    """
    check_samples(samples, lobes)
    rng = np.random.default_rng(seed)
    theta0 = np.stack([_starts(rng, starts, lobes, samples.f[:, c]) for c in range(3)])
    if initial is not None:
        guess = np.stack([np.concatenate([
            [np.log(max(float(initial.diffuse[c]), 1e-6))], np.asarray(initial.Cxy)[:, c],
            np.asarray(initial.Cz)[:, c], np.log(np.asarray(initial.n)[:, c])])
            for c in range(3)])
        theta0 = np.concatenate([theta0, guess[:, None, :]], axis=1)
    w_cos = np.sqrt(samples.weight) * np.clip(samples.wi[:, 2], 0.0, 1.0)
    scale = np.sqrt(np.mean((w_cos[:, None] * samples.f) ** 2, axis=0)) + 1e-300
    units = [(theta0[c], samples.wi, samples.wo, samples.f[:, c], w_cos, scale[c])
             for c in range(3)]
    solved = list((map_units or _map_here)(solve_channel, units))
    theta, loss, ok, steps = (np.stack(a) for a in zip(*solved, strict=True))
    loss = np.where(np.isfinite(loss) & np.all(np.isfinite(theta), axis=-1), loss, np.inf)
    if not np.all(np.isfinite(loss).any(axis=1)):
        raise FitError("every start failed for some channel; try more --starts",
                       samples.path)
    best = np.argmin(loss, axis=1)
    chosen = theta[np.arange(3), best]  # (3, P)
    params = lafortune.Lafortune(
        diffuse=np.exp(chosen[:, 0]), Cxy=chosen[:, 1:1 + lobes].T,
        Cz=chosen[:, 1 + lobes:1 + 2 * lobes].T, n=np.exp(chosen[:, 1 + 2 * lobes:]).T)
    with jax.enable_x64(True):
        f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
        model = np.asarray(lafortune.brdf(lafortune.Lafortune(*(f64(a) for a in params)),
                                          f64(samples.wi), f64(samples.wo)))
    w = samples.weight[:, None]
    rel = np.sqrt(np.sum(w * (model - samples.f) ** 2, axis=0) / np.sum(w * samples.f**2, axis=0))
    if not all(np.all(np.isfinite(np.asarray(a))) for a in (*params, rel)):
        raise FitError("the fit failed: a lobe parameter or the error is not finite",
                       samples.path)
    return BRDFFit(params, rel, loss, best, ok, steps)


# A channel is reported when its relative RMS error is above WORSE × the best channel's
# and above POOR (the shipped samples fit at 1.9 % in every channel; 2 lobes from 2 starts
# left G at 54 %, its lobes collapsed to a flat line, and the render's highlights magenta).
WORSE, POOR = 2.0, 0.05


def fit_warnings(result: BRDFFit) -> list[str]:
    """What the fit says to look at: a channel whose diffuse albedo is above 1 (values in
    other units), and one line per channel that fits far worse than the best one (a start
    stuck in a local minimum: its highlight colour comes out wrong)."""
    best = int(np.argmin(result.rel_rms))
    out = []
    rho = np.asarray(result.params.diffuse, float)  # a surface cannot reflect more than
    if np.any(rho > ALBEDO_WARN):  # it receives; a fit trades a little of it with the lobes
        said = ", ".join(f"{name} {r:.3g}" for name, r in zip("RGB", rho, strict=True))
        out.append(f"diffuse albedo {said}: above 1 is more light out than in; are the BRDF "
                   "values scaled (0-255, percent)? fit-brdf reads them in 1/sr")
    for k, name in enumerate("RGB"):
        e = float(result.rel_rms[k])
        if e > POOR and e > WORSE * float(result.rel_rms[best]):
            out.append(f"channel {name} fits at {e:.1%} against {'RGB'[best]}'s "
                       f"{float(result.rel_rms[best]):.1%}: its lobes are likely stuck in a "
                       "local minimum, which tints the highlights; try more --starts (e.g. "
                       f"{max(4 * result.losses.shape[1], 32)}) or another --seed, and see "
                       "the report")
    return out


def write_report(samples: BRDFSamples, result: BRDFFit, path, slices=(0, 30, 60, 75)) -> None:
    """In-plane slices at a few incident angles: samples near the plane vs the fitted lobes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    # Rotate every sample so that its incident direction has azimuth 0.
    phi_i = np.arctan2(samples.wi[:, 1], samples.wi[:, 0])
    c, s = np.cos(-phi_i), np.sin(-phi_i)
    wo_x = c * samples.wo[:, 0] - s * samples.wo[:, 1]
    wo_y = s * samples.wo[:, 0] + c * samples.wo[:, 1]
    theta_i = np.degrees(np.arccos(np.clip(samples.wi[:, 2], -1, 1)))
    signed_out = np.degrees(np.arctan2(-wo_x, samples.wo[:, 2]))  # + toward the mirror side
    in_plane = np.abs(wo_y) < math.sin(math.radians(5))
    t = np.radians(np.linspace(-89, 89, 357))
    params = lafortune.Lafortune(*(np.asarray(a) for a in result.params))
    fig, axes = plt.subplots(1, len(slices), figsize=(4 * len(slices), 3.6), sharey=True,
                             constrained_layout=True)
    for ax, angle in zip(np.atleast_1d(axes), slices, strict=True):
        a = math.radians(angle)
        wi = np.broadcast_to([math.sin(a), 0.0, math.cos(a)], (len(t), 3))
        wo = np.stack([-np.sin(t), np.zeros_like(t), np.cos(t)], axis=-1)
        model = np.asarray(lafortune.brdf(params, wi, wo))
        near = in_plane & (np.abs(theta_i - angle) < 2.5)
        for k, colour in enumerate(("tab:red", "tab:green", "tab:blue")):
            ax.plot(np.degrees(t), model[:, k], color=colour, lw=1.2)
            ax.plot(signed_out[near], samples.f[near, k], ".", ms=3, color=colour, alpha=0.6)
        ax.set(title=f"θ_in = {angle}° (plane of incidence)", xlabel="θ_out (°, + = mirror side)",
               yscale="log")
    np.atleast_1d(axes)[0].set_ylabel("BRDF (1/sr): lines fit, dots samples")
    errors = ", ".join(f"{e:.1%}" for e in result.rel_rms)
    fig.suptitle(f"Lafortune fit, {len(params.n)} lobes: relative RMS error R, G, B = {errors}")
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=100)
    plt.close(fig)
