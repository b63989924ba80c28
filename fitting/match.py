"""Computer colour matching: the concentrations of given components (and a film's thickness)
whose two-constant Kubelka–Munk mixture (`jaxskin.mixture`) best matches a target.

`jaxskin match TARGET.csv --from A.json,B.json,... -o DIR`.

- **Components** are calibrated materials (S, K per mm). On different wavelength grids
  they are resampled (linearly in log S, log K, as the renderer does) onto the range they
  all cover, as a colour lab compares instruments only where both measured; that range
  must include 400–700 nm (`read_components`).
- **Colour**: CIELAB under D65 with the CIE 1964 10° observer by default, the
  colour-matching industry's convention (ASTM D2244, ISO 105-J03 practice), or the 2°
  observer the renderer and `jaxskin fit-skin` use; XYZ by colour-science's ASTM E308
  weights on a 5 nm grid over the range the target and the components share within
  380–780 nm; ΔE is CIEDE2000. A spectral target's match also gets its metamerism: ΔE2000
  under illuminant A and with the other observer.
- **Unknowns**: concentrations by a softmax of unbounded logits (non-negative, summing to
  1: the base is one of the components, its share what the pigments leave); a film's
  thickness as log X mapped into [`THICKNESS_MM`] by a sigmoid.
- **Loss** (Levenberg–Marquardt, optimistix, float64): the residuals are ΔL*, Δa*, Δb*
  and, for a spectral target, `spectral_weight`·100·(R − R_target)/√n, so that the loss is
  ΔE*ab² + w²·(100 × RMS ΔR)². Colour first, because a shade is judged by eye under the
  stated light; the spectral term, small by default (w = 0.05), picks among mixtures of the
  same colour the one closest in spectrum (the least metameric, which holds its match
  under other lights) and makes the answer unique when more than three components could
  reach the colour. A target mixed from the components themselves has both terms zero at
  its own concentrations. A weak prior (1e-3·z) on the logits keeps a component that is
  not wanted at a share of about 1e-5 instead of driving its logit to −∞.
- Several starts (equal shares, each component dominant, random), all vmapped in one
  compiled program; the lowest loss wins.
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

from jaxskin import km, mixture
from jaxskin.formats import read_material
from jaxskin.io import FitError, InputError

__all__ = ["GAMUT_DE", "NEEDED", "OBSERVERS", "THICKNESS_MM", "Components", "Match",
           "colour_name", "colour_weights", "delta_e2000", "fit", "lab", "read_components",
           "resample_target"]

# colour-science's names of the two CIE observers, by field of view in degrees
OBSERVERS = {10: "CIE 1964 10 Degree Standard Observer", 2: "CIE 1931 2 Degree Standard Observer"}
NEEDED = (400.0, 700.0)  # nm: colour needs at least this much of the spectrum
STEP = 5  # nm: the fit's grid (ASTM E308 interval)
THICKNESS_MM = (1e-4, 10.0)  # a film's fitted thickness stays within (0.1 µm to 1 cm)
GAMUT_DE = 1.0  # ΔE2000 above this: no mixture of the components reaches the target
PRIOR = 1e-3  # on the logits (see the module docstring)


@dataclasses.dataclass(frozen=True)
class Components:
    """The components on one grid: `names`, `paths`, `S`, `K (m, n)` per mm at
    `wavelength_nm (n,)`; `extrapolate`: their shared rule (None if any has none);
    `notes`: lines about what was resampled."""

    names: list[str]
    paths: list[Path]
    wavelength_nm: np.ndarray
    S: np.ndarray
    K: np.ndarray
    extrapolate: str | None
    notes: list[str]


def read_component(path):
    """One component's `formats.MaterialFile`; a material of unknown thickness (film
    coefficients `S_film`, `K_film`, no per-mm values) is refused with a line saying why."""
    path = Path(path)
    if not path.exists():
        raise InputError("no such material file", path)
    try:
        return read_material(path)
    except InputError as e:
        if e.key == "S_film":  # `read_material`'s words are for a scene
            raise InputError("a material of unknown thickness (S_film, K_film): mixing adds "
                             "S and K per mm of each pure component; calibrate it with "
                             "--thickness MM", path, key="S_film") from None
        raise


def read_components(paths, names=None) -> Components:
    """Read each material and put them on one grid: their own if they share it, else the
    union of their wavelengths over the range all of them cover (S, K resampled linearly in
    log S, log K, with a note). `InputError` if that range misses part of 400–700 nm, or
    if two components have one name."""
    files = [read_component(p) for p in paths]
    names = [f.name for f in files] if names is None else list(names)
    for i, n in enumerate(names):
        if n in names[:i]:
            raise InputError(f"two components are named {n!r} ({files[names.index(n)].path} "
                             f"and this one); the match names each by its material name",
                             files[i].path, key="name")
    lo = max(f.wavelength_nm[0] for f in files)
    hi = min(f.wavelength_nm[-1] for f in files)
    narrow = min(files, key=lambda f: min(f.wavelength_nm[-1], NEEDED[1])
                 - max(f.wavelength_nm[0], NEEDED[0]))
    if lo > NEEDED[0] or hi < NEEDED[1]:
        raise InputError(f"the components together cover {lo:g}-{hi:g} nm (this one "
                         f"{narrow.wavelength_nm[0]:g}-{narrow.wavelength_nm[-1]:g}); a "
                         f"mixture's colour needs {NEEDED[0]:g}-{NEEDED[1]:g} nm", narrow.path,
                         key="wavelength_nm")
    notes = []
    same = all(np.array_equal(f.wavelength_nm, files[0].wavelength_nm) for f in files)
    if same:
        wl = files[0].wavelength_nm
        S = np.stack([f.S for f in files])
        K = np.stack([f.K for f in files])
    else:
        wl = np.unique(np.concatenate([f.wavelength_nm for f in files]))
        wl = wl[(wl >= lo) & (wl <= hi)]
        S = np.stack([np.exp(np.interp(wl, f.wavelength_nm, np.log(f.S))) for f in files])
        K = np.stack([np.exp(np.interp(wl, f.wavelength_nm, np.log(f.K))) for f in files])
        notes.append(f"the components are on different wavelength grids: S, K resampled "
                     f"(linearly in log S, log K) onto the {lo:g}-{hi:g} nm all of them cover")
    rules = {f.extrapolate for f in files}
    extrapolate = rules.pop() if len(rules) == 1 else None
    if extrapolate is None and None not in {f.extrapolate for f in files}:
        extrapolate = "hold"  # all extend, in different ways: the mixture holds its ends
        notes.append("the components extend beyond their wavelengths in different ways "
                     f"({', '.join(sorted(rules | {f.extrapolate for f in files}))}): the "
                     "mixture holds its end values (\"extrapolate\": \"hold\")")
    return Components(names, [f.path for f in files], wl, S, K, extrapolate, notes)


def colour_name(observer: int = 10, illuminant: str = "D65") -> str:
    """How the colours are computed, in words (for the JSON and the messages)."""
    return f"CIELAB, {illuminant}, {OBSERVERS[observer][:8]} {observer}° observer; ΔE CIEDE2000"


@functools.cache
def _weights(start: int, stop: int, observer: int, illuminant: str) -> np.ndarray:
    import warnings

    import colour

    shape = colour.SpectralShape(start, stop, STEP)
    basis = colour.MultiSpectralDistributions(np.eye(len(shape.wavelengths)), shape.wavelengths)
    cmfs = colour.MSDS_CMFS[OBSERVERS[observer]]
    with warnings.catch_warnings():  # colour announces the (expected) shape alignments
        warnings.simplefilter("ignore", colour.utilities.ColourRuntimeWarning)
        W = colour.msds_to_XYZ(basis, cmfs, colour.SDS_ILLUMINANTS[illuminant],
                               method="ASTM E308")
    W = np.asarray(W, np.float64) / 100.0
    W.setflags(write=False)
    return W


def colour_weights(lo: float, hi: float, observer: int = 10,
                   illuminant: str = "D65") -> tuple[np.ndarray, np.ndarray]:
    """The fit's grid over `lo`–`hi` nm (5 nm steps inside it, within 380–780) and its
    weights `W (n, 3)`: XYZ = R @ W under `illuminant` for the `observer` (10 or 2
    degrees), a perfect reflector's Y = 1 over the grid (so CIELAB is relative to the white
    of the same range)."""
    start = int(math.ceil(max(lo, 380.0) / STEP) * STEP)
    stop = int(math.floor(min(hi, 780.0) / STEP) * STEP)
    W = _weights(start, stop, observer, illuminant)
    return np.arange(start, stop + 1, STEP, dtype=np.float64), W / W.sum(axis=0)[1]


def lab(R, W):
    """CIELAB of reflectances `R (..., n)` with weights `W (n, 3)` (`colour_weights`),
    relative to the white R = 1; differentiable (the cube root's branch point is kept out of
    the gradient by a double `where`)."""
    white = jnp.sum(W, axis=0)
    t = (R @ W) / white
    d3 = (6.0 / 29.0) ** 3
    big = t > d3
    f = jnp.where(big, jnp.cbrt(jnp.where(big, t, 1.0)), t / (3 * (6.0 / 29.0) ** 2) + 4.0 / 29.0)
    return jnp.stack([116.0 * f[..., 1] - 16.0, 500.0 * (f[..., 0] - f[..., 1]),
                      200.0 * (f[..., 1] - f[..., 2])], axis=-1)


def delta_e2000(lab1, lab2) -> np.ndarray:
    """CIEDE2000 between CIELAB values (colour-science)."""
    import colour

    return np.asarray(colour.delta_E(np.asarray(lab1), np.asarray(lab2), method="CIE 2000"))


def resample_target(wavelengths, R, grid) -> np.ndarray:
    """A target spectrum on the fit's grid (linear interpolation)."""
    return np.interp(grid, np.asarray(wavelengths, np.float64), np.asarray(R, np.float64))


@dataclasses.dataclass(frozen=True)
class Match:
    """The result of `fit`: `concentrations (m,)` by component `names`; `thickness_mm`
    (None: opaque); on `wavelength_nm (n,)` the target (None for a CIELAB target) and the
    match's reflectance; their CIELAB (`colour_name(observer)`), `dE2000`, `rms`
    reflectance difference (None for CIELAB), `converged`, `steps`, `loss`,
    `thickness_fitted`, `hides_background` (the film reflects within 0.001 of the opaque
    mixture in every band: a fitted thickness is then only a lower bound); `metamerism`:
    for a spectral target, ΔE2000 between target and
    match under illuminant A and with the other observer (a match that holds under every
    light and for every eye has both near 0)."""

    names: list[str]
    concentrations: np.ndarray
    thickness_mm: float | None
    thickness_fitted: bool
    wavelength_nm: np.ndarray
    R_target: np.ndarray | None
    R_match: np.ndarray
    lab_target: np.ndarray
    lab_match: np.ndarray
    dE2000: float
    rms: float | None
    converged: bool
    steps: int
    loss: float
    observer: int = 10
    metamerism: dict | None = None
    hides_background: bool = False
    saunderson: tuple[float, float] | None = None  # (k1, k2) where the target has a surface

    @property
    def in_gamut(self) -> bool:
        """Whether the match reaches the target to within `GAMUT_DE`."""
        return self.dE2000 <= GAMUT_DE


def _unpack(p, m, film):
    c = jax.nn.softmax(p[:m])
    if not film:
        return c, None
    lo, hi = (math.log(v) for v in THICKNESS_MM)
    return c, jnp.exp(lo + (hi - lo) * jax.nn.sigmoid(p[m]))


def _residuals(p, args, film, fit_x):
    S, K, W, lab_t, R_t, w, X_fixed, background, surface = args
    m = S.shape[0]
    c, X = _unpack(p, m, fit_x)
    X = X if fit_x else X_fixed
    R = km.saunderson(mixture.reflectance(S, K, c, X if film else None,
                                          background if film else None), *surface)
    out = [lab(R, W) - lab_t, PRIOR * p[:m]]
    if R_t is not None:
        out.append(w * 100.0 * (R - R_t) / math.sqrt(R.shape[-1]))
    return jnp.concatenate(out)


@functools.partial(jax.jit, static_argnames=("film", "fit_x", "max_steps"))
def _solve(p0, S, K, W, lab_t, R_t, w, X_fixed, background, surface, film, fit_x,
           max_steps=400):
    # The damped step by Cholesky of the small normal equations (as fitting.skin): less to
    # compile than the default QR.
    solver = optx.LevenbergMarquardt(rtol=1e-10, atol=1e-12,
                                     linear_solver=lx.Normal(lx.Cholesky()))
    args = (S, K, W, lab_t, R_t, w, X_fixed, background, surface)
    residuals = functools.partial(_residuals, film=film, fit_x=fit_x)

    def one(p):
        sol = optx.least_squares(residuals, solver, p, args, max_steps=max_steps, throw=False)
        r = residuals(sol.value, args)
        return sol.value, jnp.sum(r * r), sol.result == optx.RESULTS.successful, \
            sol.stats["num_steps"]

    return jax.vmap(one)(p0)


def _starts(m, starts, fit_x, seed):
    """`(starts, m [+1])`: equal shares, each component dominant, then random logits; a
    fitted thickness starts at 2, 20 and 200 µm in turn."""
    rng = np.random.default_rng(seed)
    z = rng.normal(0.0, 1.5, (max(starts, 1), m))
    z[0] = 0.0
    for i in range(min(m, starts - 1)):
        z[i + 1] = 0.0
        z[i + 1, i] = 3.0
    if not fit_x:
        return z
    lo, hi = (math.log(v) for v in THICKNESS_MM)
    x = np.log([0.002, 0.02, 0.2])[np.arange(len(z)) % 3]
    t = (x - lo) / (hi - lo)
    return np.concatenate([z, np.log(t / (1 - t))[:, None]], axis=1)


def fit(components: Components, target_wavelengths=None, target_R=None, target_lab=None,
        thickness_mm=None, background=None, spectral_weight: float = 0.05, starts: int = 12,
        seed: int = 0, observer: int = 10, saunderson=(0.0, 0.0)) -> Match:
    """Match a target with a mixture of `components`.

    **Arguments:**

    - `components`: `read_components`.
    - `target_wavelengths (k,)`, `target_R (k,)`: a target spectrum (0–1); or
      `target_lab (3,)`: a target colour (`colour_name(observer)`).
    - `thickness_mm`: "fit" to fit a film's thickness, a number to hold it, None for an
      opaque mixture; a film needs `background`: `(wavelengths, R)` or a number (0–1).
    - `spectral_weight`: w of the loss (module docstring); unused for a CIELAB target.
    - `starts`, `seed`: the number of starts and the seed of the random ones.
    - `observer`: 10 (default, the colour-matching industry's) or 2 (the renderer's) degrees.
    - `saunderson`: `(k1, k2)` of a target measured with the surface (specular included):
      the mixture's body reflectance is compared after `km.saunderson`, as
      `jaxskin calibrate --saunderson` reads such readings, and a film's `background` is
      taken as read the same way (made internal); (0, 0) (default) compares it as it is.

    **Returns:** a `Match`. **Raises:** `InputError` if the target and components share
    less than 400–700 nm; `FitError` if every start failed.
    """
    film = thickness_mm is not None
    lo, hi = components.wavelength_nm[0], components.wavelength_nm[-1]
    if target_R is not None:
        tw = np.asarray(target_wavelengths, np.float64)
        lo, hi = max(lo, tw[0]), min(hi, tw[-1])
    if isinstance(background, tuple):
        lo, hi = max(lo, background[0][0]), min(hi, background[0][-1])
    if lo > NEEDED[0] or hi < NEEDED[1]:
        raise InputError(f"the target, the components (and background) share only "
                         f"{lo:g}-{hi:g} nm; matching a colour needs {NEEDED[0]:g}-"
                         f"{NEEDED[1]:g} nm")
    grid, W = colour_weights(lo, hi, observer)
    wl = components.wavelength_nm
    S = np.stack([np.exp(np.interp(grid, wl, np.log(s))) for s in components.S])
    K = np.stack([np.exp(np.interp(grid, wl, np.log(k))) for k in components.K])
    if background is None:
        Rg = np.zeros(len(grid))
    elif isinstance(background, tuple):
        Rg = resample_target(*background, grid)
    else:
        Rg = np.full(len(grid), float(background))
    if background is not None and any(saunderson):  # a background read as the target was
        Rg = np.clip(np.asarray(km.saunderson_inverse(Rg, *saunderson)), 0.0, 1.0)
    m, fit_x = len(components.names), thickness_mm == "fit"
    p0 = _starts(m, starts, fit_x, seed)
    with jax.enable_x64(True):
        f64 = functools.partial(jnp.asarray, dtype=jnp.float64)
        R_t = None if target_R is None else resample_target(tw, target_R, grid)
        lab_t = np.asarray(lab(f64(R_t), f64(W))) if R_t is not None else np.asarray(
            target_lab, np.float64)
        X_fixed = f64(thickness_mm if film and not fit_x else 1.0)
        p, loss, ok, steps = (np.asarray(a) for a in _solve(
            f64(p0), f64(S), f64(K), f64(W), f64(lab_t), None if R_t is None else f64(R_t),
            f64(spectral_weight), X_fixed, f64(Rg), f64(saunderson), film, fit_x))
        good = np.isfinite(loss) & np.all(np.isfinite(p), axis=1)
        if not good.any():
            raise FitError("the match failed: every start ended with a non-finite loss")
        best = int(np.argmin(np.where(good, loss, np.inf)))
        c, X = _unpack(f64(p[best]), m, fit_x)
        X = X if fit_x else (float(thickness_mm) if film else None)
        R = np.asarray(km.saunderson(mixture.reflectance(f64(S), f64(K), c, X, f64(Rg) if film
                                                         else None), *saunderson))
        hides = film and float(np.max(np.abs(R - np.asarray(km.saunderson(mixture.reflectance(
            f64(S), f64(K), c), *saunderson))))) < 1e-3
        c = np.asarray(c)
    lab_m = _lab_np(R, W)
    lab_t = _lab_np(R_t, W) if R_t is not None else lab_t
    metamerism = None
    if R_t is not None:
        other = 2 if observer == 10 else 10
        W_a, W_o = colour_weights(lo, hi, observer, "A")[1], colour_weights(lo, hi, other)[1]
        metamerism = {
            "dE2000 under illuminant A": float(delta_e2000(_lab_np(R_t, W_a), _lab_np(R, W_a))),
            f"dE2000 with the {other}° observer": float(delta_e2000(_lab_np(R_t, W_o),
                                                                   _lab_np(R, W_o)))}
    return Match(
        names=list(components.names), concentrations=c,
        thickness_mm=None if X is None else float(X), thickness_fitted=fit_x,
        wavelength_nm=grid, R_target=R_t, R_match=R, lab_target=lab_t, lab_match=lab_m,
        dE2000=float(delta_e2000(lab_t, lab_m)),
        rms=None if R_t is None else float(np.sqrt(np.mean((R - R_t) ** 2))),
        converged=bool(ok[best]), steps=int(steps[best]), loss=float(loss[best]),
        observer=observer, metamerism=metamerism, hides_background=hides,
        saunderson=tuple(float(k) for k in saunderson) if any(saunderson) else None)


def _lab_np(R, W) -> np.ndarray:
    """CIELAB by colour-science (not `lab`): the figures reported are computed another way
    than the loss."""
    import colour

    xyz = np.asarray(R) @ W
    white = W.sum(axis=0)
    return np.asarray(colour.XYZ_to_Lab(xyz / white[1], colour.XYZ_to_xy(white)))
