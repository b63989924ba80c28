"""Inverse rendering: scene values and texture-space maps fitted to an image.

`jaxskin fit-image SCENE TARGET.png --fit KEY[,KEY...]` asks which values of the scene, seen
from its camera, make the target. The renderer is `render.render_prepared`, unchanged; the fit
moves some of its parameters:

- **Scalars** (`FitKey.kind == "scalar"` or `"vector"`): any differentiable scene value the
  scene's model uses (`Scene.params`: melanin, blood, light, exposure, k_bump, layer
  thickness, roughness, specular …). Each is bounded by its schema range through
  x = lo + (hi − lo) σ(z); `light.direction` is free (the renderer normalises it);
  `material.lafortune`, a Lafortune scene's lobes, with ρd and n through exp.
- **Maps** (`"map"`): per-texel factors in texture space, `(H, W)` like the texture, that
  multiply their scalar as a scene's greyscale image does (`render.texel_map`):
  `layer.NAME.map` (× the layer's thickness_mm) and `skin.melanin_map` (× skin.melanin),
  kept in [0, the schema's top] by a sigmoid, log-like near 0 (a step changes a texel by
  a fraction of its value: thicknesses span decades). A smoothness prior,
  a smoothed total variation between neighbouring texels on the mesh, fills the texels the
  camera does not see and damps the noise.

The loss is the weighted mean squared difference of display values (sRGB, clipped to [0, 1]
as a PNG holds them) over the pixels the mesh covers fully (and the mask, if any), plus the
prior. Optimisers (optimistix, stepped one iteration at a time for the progress bar):

- scalars only: Levenberg–Marquardt (`optimistix.LevenbergMarquardt`) on the residual image,
  its Jacobian by forward mode (one JVP per scalar);
- with maps: Levenberg–Marquardt with a per-texel block-diagonal Gauss–Newton matrix
  (`_gauss_newton`, `texel_blocks`; why and what it measured: `MAP_SOLVER_NOTE`). Adam
  (`optimistix.OptaxMinimiser(optax.adam)`), L-BFGS and nonlinear CG stay as `solver=`
  choices for comparison.

How well an image can pin a map at all is `map_bounds`: the Cramér–Rao bound of each
texel's log value from the noise and the image's sensitivity to it.

The optics stays in `jaxskin.render`; reading and writing files is the CLI's
(`jaxskin.cli`, `write_report` here for the PNG report).
"""

from __future__ import annotations

import dataclasses
import difflib
import functools
import math
import time
import warnings
from collections.abc import Callable
from pathlib import Path

import equinox as eqx
import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from jaxskin import cluster, render
from jaxskin.io import InputError, atomic_write
from jaxskin.scene import LAYER_SCHEMA, SCHEMA, SKIN_MAPS, Scene
from jaxskin.view import pixel_entries

__all__ = ["DEGENERATE", "FitKey", "ImageFit", "MAP_SCALARS", "blur_gain", "fit", "fit_keys",
           "map_bounds", "noise_sigma", "pcg", "texel_blocks", "texel_jacobian", "view_diagonal",
           "view_matrix", "weights", "write_report"]

# A map key → the scalar it multiplies (the biophysical model's maps go here too). Layer
# maps, `layer.NAME.map`, multiply `layer.NAME.thickness_mm`.
MAP_SCALARS = {k: scalar for k, (scalar, _) in SKIN_MAPS.items()}
# Pairs of keys that trade off against each other in an image (warned about when fitted
# together): exact scale ambiguities and near ones.
DEGENERATE = {
    frozenset({"camera.exposure", "light.intensity"}):
        "exposure and light intensity both scale the image (exactly, with light.ambient)",
    frozenset({"camera.exposure", "light.ambient"}):
        "exposure and ambient light both scale the image (exactly, with light.intensity)",
    frozenset({"light.intensity", "material.melanin"}):
        "albedo against light intensity: melanin darkens much as less light does",
    frozenset({"light.intensity", "material.blood"}):
        "albedo against light intensity: blood darkens much as less light does",
    frozenset({"light.intensity", "skin.melanin"}):
        "albedo against light intensity: melanin darkens much as less light does",
    frozenset({"camera.exposure", "skin.melanin"}):
        "albedo against exposure: melanin darkens much as a lower exposure does",
}
MAP_SOLVER_NOTE = (
    "Maps: Levenberg–Marquardt on a block-diagonal Gauss–Newton matrix. A texel's colour "
    "depends on its own values (the SSS blur aside), so JᵀJ is nearly block-diagonal: per "
    "texel an L × L block for L maps, from three reverse-mode passes of the texture-space "
    "colour (one per channel: `texel_jacobian`) and the exact diagonal of the view map's "
    "AᵀDA (`view_matrix`); the SSS blur's share "
    "counted by its own-texel gain (`blur_gain`). The prior's Hessian enters exactly, the "
    "coupled system solved by block-preconditioned CG in texture space (cheap: no render; "
    "inexact, to 0.1 of the residual, as usual in Gauss–Newton). "
    "optimistix.LevenbergMarquardt / GaussNewton take their curvature from the residual's "
    "Jacobian operator, which does not expose the per-texel structure: materialising JᵀJ is "
    "out of reach (a column per texel), and CG through J costs a JVP and a VJP of the whole "
    "render per inner iteration; so the step is our own, in the loop `_solve` runs for the "
    "optimistix solvers. Measured against Adam (benchmarks/RESULTS.md, 'fit-image'): see "
    "there. L-BFGS and NonlinearCG (optimistix, float32) never left the start's loss in "
    "150 steps on the makeup face (their line searches rejected every step).")
STEP_MAX = 1.0  # the Gauss–Newton step's largest change of a coordinate (e ≈ 2.7× a texel)
GN_RTOL = 1e-5  # stop when the Gauss–Newton model predicts less than this share of the loss
# The inner conjugate-gradient solve of each Gauss–Newton step: an inexact Newton step, to
# 0.1 of the right-hand side (at 512² on the makeup face: 1-2 iterations and the same
# predicted decrease to 0.3 %, where 1e-3 ran the 100 iterations, 1.9 s a step).
CG_RTOL = 0.1
CG_STEPS = 100  # … and its most iterations (each one texture-space prior HVP: cheap)
_DEBUG = bool(__import__("os").environ.get("JAXSKIN_FIT_DEBUG"))
ADAM_RATE = 0.3  # per step, in the transformed (log-like) coordinates: ~35 % at most
PRIOR_EPS = 0.01  # the total variation's smoothing, in map units: sqrt(d² + ε²) − ε


@dataclasses.dataclass(frozen=True)
class FitKey:
    """One fitted value: `key` (a `Scene.params` key or a map key), `kind` (`"scalar"`,
    `"vector"`, `"map"` or `"lafortune"`: the lobes, ρd and n kept positive), its bounds
    `lo`, `hi` (None: free) and, for a map, the scalar it multiplies and its transform
    (`"sigmoid"`: in [0, hi/scalar], log-like near 0)."""

    key: str
    kind: str
    lo: float | None = None
    hi: float | None = None
    scalar: str | None = None
    transform: str | None = None

    @property
    def span(self) -> float:
        """hi − lo of the key's range (1 for a key without one)."""
        return float(self.hi - self.lo) if self.lo is not None else 1.0


def map_keys(scene: Scene) -> dict[str, str]:
    """The map keys a scene has, each → the scalar it multiplies."""
    if scene.config.spectral is None:
        return {}
    out = {f"layer.{layer.name}.map": f"layer.{layer.name}.thickness_mm"
           for layer in scene.layers}
    out.update({k: s for k, s in MAP_SCALARS.items() if s in scene.params})
    return out


def _schema(key: str):
    parts = key.split(".")
    if len(parts) == 3 and parts[0] == "layer":
        return LAYER_SCHEMA.get(parts[2])
    return SCHEMA.get(key)


def fit_keys(scene: Scene, text: str, where: str = "--fit") -> tuple[FitKey, ...]:
    """`--fit KEY[,KEY...]` for `scene`, checked: every key known, differentiable and used by
    the scene's model; no key twice; no scalar with its own map (the pair has one scale).
    Warns (`warnings.warn`) about the pairs in `DEGENERATE`. `InputError` otherwise."""
    names = [k.strip() for k in text.split(",")]
    if not names or any(not k for k in names):
        raise InputError(f"expected KEY[,KEY...], got {text!r}", where)
    params, maps = scene.params, map_keys(scene)
    out = []
    for key in names:
        if names.count(key) > 1:
            raise InputError("this key is given twice", where, key=key)
        if key in maps:
            scalar = maps[key]
            if scalar in names:
                raise InputError(f"fit the map or its scalar '{scalar}', not both: the map "
                                 "multiplies it, so only their product is seen", where, key=key)
            spec = _schema(scalar)
            out.append(FitKey(key, "map", spec.lo, spec.hi, scalar, "sigmoid"))
            continue
        spec = _schema(key)
        if key == "material.lafortune" and key in params:
            out.append(FitKey(key, "lafortune"))
            continue
        if key not in params:
            fittable = list(params) + list(maps)
            layers = [layer.name for layer in scene.layers]
            layer = key.split(".")[1] if key.startswith("layer.") and key.count(".") >= 2 \
                else None
            if layer is not None and layer not in layers:  # said "not used by this scene's
                # material model" (a trial)
                near = difflib.get_close_matches(key, fittable, n=1, cutoff=0.5)
                why = (f"names no layer of this scene (its layers: {', '.join(layers) or 'none'})"
                       + (f"; did you mean '{near[0]}'?" if near else ""))
            elif spec is not None and not spec.param:
                why = ("is not differentiable: it is static (it decides which stages run or "
                       "their sizes)")
            elif spec is not None:
                why = (f"is not used by this scene's material model "
                       f"({scene.values['material.model']!r})")
            elif key.endswith("_map") or key.endswith(".map"):
                why = "is not a map of this scene"
            else:
                near = difflib.get_close_matches(key, fittable, n=1, cutoff=0.5)
                why = "is unknown" + (f" (did you mean '{near[0]}'?)" if near else "")
            raise InputError(f"{why}; this scene's fittable keys: {', '.join(fittable)}",
                             where, key=key)
        if spec.kind == "vec3":
            out.append(FitKey(key, "vector"))
        else:
            out.append(FitKey(key, "scalar", spec.lo, spec.hi))
    keys = {k.key for k in out}
    pairs = dict(DEGENERATE)
    melanin = keys & {"skin.melanin", "skin.melanin_map"}
    thickness = {k for k in keys if k.startswith("layer.") and k.endswith(("thickness_mm",
                                                                          ".map"))}
    for a in melanin:
        for b in thickness:
            pairs[frozenset({a, b})] = ("melanin against thickness: more melanin and a "
                                        "thicker tinted layer both darken the skin")
    for pair, why in pairs.items():
        if pair <= keys:
            a, b = sorted(pair)
            warnings.warn(f"fitting {a} and {b} together: {why}; fix one of them (the fit "
                          "finds one of many equally good answers)", stacklevel=2)
    return tuple(out)


# --- the parameter transforms -------------------------------------------------------------

def _unit(fk: FitKey, params: dict) -> float:
    """A map's fitting scale: its scalar's value (the schema's top when that is 0)."""
    value = float(params[fk.scalar])
    return value if value > 0 else float(fk.hi)


def _to_z(fk: FitKey, value, unit: float = 1.0):
    if fk.kind == "lafortune":  # ρd and the exponents n positive (log), Cxy and Cz free
        return value._replace(diffuse=jnp.log(jnp.maximum(value.diffuse, 1e-6)),
                              n=jnp.log(jnp.maximum(value.n, 1e-6)))
    return _to_z_array(fk, value, unit)


def _to_z_array(fk: FitKey, value, unit: float = 1.0):
    """The unconstrained coordinate of a value (inverse of `_from_z`), kept off the bounds
    so that it is finite: by 1e-3 of the range for a scalar, 1e-7 for a map (whose range,
    up to the schema's top in units of its scalar, is wide: 0.01 mm of 10 mm)."""
    x = np.asarray(value, np.float64)
    if fk.kind == "vector":
        return x
    lo, hi = (0.0, fk.hi / unit) if fk.kind == "map" else (fk.lo, fk.hi)
    eps = 1e-7 if fk.kind == "map" else 1e-3
    f = np.clip((x - lo) / (hi - lo), eps, 1 - eps)
    return np.log(f) - np.log1p(-f)


def _start_scale(z) -> float:
    """The factor c a scalar's coordinate is fitted in (the solver sees c z): 4 f (1 − f)
    at its start, f = σ(z) its place in its range, so that a change of the solver's
    coordinate moves the value as much at the start as a change of z does mid-range. A
    start at a range's end (f held at 1e-3: `skin.melanin = 0`, a thickness of 0) has
    the sigmoid's slope near 0 there, and Levenberg–Marquardt's damping, the same for
    every coordinate, took steps so small that it stopped at once: melanin 0 → 0.003 for
    a truth of 0.3, a blush thickness 0 → 0.01 mm for 0.04 (a trial)."""
    f = 1.0 / (1.0 + math.exp(-float(z)))
    return 4.0 * f * (1.0 - f)


def _from_z(fk: FitKey, z, unit: float = 1.0):
    if fk.kind == "lafortune":
        return z._replace(diffuse=jnp.exp(z.diffuse), n=jnp.exp(z.n))
    if fk.kind == "vector":
        return z
    lo, hi = (0.0, fk.hi / unit) if fk.kind == "map" else (fk.lo, fk.hi)
    return lo + (hi - lo) * jax.nn.sigmoid(z)


# --- the loss -------------------------------------------------------------------------------

def weights(config, params, target_alpha=None, mask=None):
    """Per-pixel weights `(H, W)`: 1 where the mesh covers the pixel fully (its coverage,
    `render`'s alpha, is 1), times the target's alpha and the mask (each in [0, 1])."""
    alpha = np.asarray(render.render(config, params, "rgba"))[..., 3]
    w = (alpha >= 1.0 - 1e-6).astype(np.float64)
    for extra in (target_alpha, mask):
        if extra is not None:
            w = w * np.clip(np.asarray(extra, np.float64), 0.0, 1.0)
    return w


def noise_sigma(image, w, min_pixels: int = 100) -> float | None:
    """The noise σ of `image (H, W, C)` (display values) estimated from its pixel-to-pixel
    variation where `w (H, W) > 0`, or `None` where fewer than `min_pixels` pixels have all
    eight neighbours there.

    Immerkær 1996, "Fast noise variance estimation": the image filtered with the 3×3 kernel
    [[1, −2, 1], [−2, 4, −2], [1, −2, 1]], which is 0 on any plane (a smooth shading
    gradient leaves no response) and turns white noise of σ into a response of standard
    deviation 6σ (the kernel's squares sum to 36); so σ = sqrt(π/2) mean|response| / 6.
    Texture, edges and wrinkles add to the response: for a render the value is an upper
    estimate of the noise, which keeps `run_command`'s warning from crying wolf."""
    img = np.asarray(image, np.float64)
    if img.ndim == 2:
        img = img[..., None]
    inside = np.asarray(w) > 0
    H, W = inside.shape
    if H < 3 or W < 3:
        return None
    k = np.array([[1.0, -2.0, 1.0], [-2.0, 4.0, -2.0], [1.0, -2.0, 1.0]])
    response = np.zeros((H - 2, W - 2, img.shape[-1]))
    full = np.ones((H - 2, W - 2), bool)
    for dy in range(3):
        for dx in range(3):
            response += k[dy, dx] * img[dy:dy + H - 2, dx:dx + W - 2]
            full &= inside[dy:dy + H - 2, dx:dx + W - 2]
    if full.sum() < min_pixels:
        return None
    return float(np.sqrt(np.pi / 2.0) * np.abs(response[full]).mean() / 6.0)


# fit-image warns when its RMS ends above this many times the target's noise (and above
# half an 8-bit step, the least difference a PNG can hold).
ABOVE_NOISE = 3.0


def _pairs(mask: np.ndarray):
    """Neighbouring texel pairs (right and down) with both texels on the mesh: two index
    arrays into the flattened texture."""
    H, W = mask.shape
    idx = np.arange(H * W).reshape(H, W)
    a = [idx[:, :-1][mask[:, :-1] & mask[:, 1:]], idx[:-1][mask[:-1] & mask[1:]]]
    b = [idx[:, 1:][mask[:, :-1] & mask[:, 1:]], idx[1:][mask[:-1] & mask[1:]]]
    return np.concatenate(a), np.concatenate(b)


def total_variation(m, pairs, eps: float = PRIOR_EPS):
    """The smoothed total variation of a map `m (H, W)` over `pairs`: the mean over pairs
    of sqrt(d² + ε²) − ε (d: the pair's difference); 0 for a constant map, ≈ mean |d| for
    steps much larger than ε, smooth everywhere."""
    flat = m.reshape(-1)
    d = flat[pairs[0]] - flat[pairs[1]]
    return jnp.mean(jnp.sqrt(d * d + eps * eps) - eps)


@dataclasses.dataclass
class ImageFit:
    """A fit's result: `params` (the scene's, with the fitted values in their units and the
    maps as factors `(H, W)`), `values` (the fitted scalars and vectors, as Python floats),
    `history` (the loss at each step), `rms` (the RMS display-value difference over the
    weighted pixels at the end), `steps`, `seconds`, `solver` (its name) and `image` (the
    fitted render, display values)."""

    params: dict
    values: dict
    history: list
    rms: float
    steps: int
    seconds: float
    solver: str
    image: np.ndarray


def _loss_of(state) -> jax.Array:
    """The loss an optimistix solver's state holds (the last accepted point's)."""
    info = getattr(state, "f_info", None)
    if info is not None and hasattr(info, "residual"):
        return jnp.sum(info.residual ** 2)
    if info is not None and hasattr(info, "f"):
        return info.f
    return state.f


def _solve(solver, fn, z0, args, steps: int, progress: Callable | None,
           stall: int | None = None):
    """Run an optimistix `solver` on `fn(z, args) -> (out, aux)` from `z0` for at most
    `steps` steps, one jitted step at a time (`args`, the render's prepared arrays, passed
    as arguments: closed over, XLA would fold them in as constants); `progress(loss)` after
    each. `stall`: also stop when the loss has not fallen by 1e-4 of itself in this many
    steps (Levenberg–Marquardt at the noise floor rejects step after step in float32, and
    its own test only runs on accepted steps). Returns the last accepted `z`, the loss
    history and the number of steps."""
    options, tags = {}, frozenset()
    f_struct, aux_struct = jax.eval_shape(fn, z0, args)
    state = solver.init(fn, z0, args, options, f_struct, aux_struct, tags)
    dynamic, static = eqx.partition(state, eqx.is_array)

    @jax.jit
    def step(z, dynamic, args):
        state = eqx.combine(dynamic, static)
        z, state, _ = solver.step(fn, z, args, options, state, tags)
        done, _ = solver.terminate(fn, z, args, options, state, tags)
        return z, eqx.filter(state, eqx.is_array), done, _loss_of(state)

    history, z = [], z0
    while len(history) < steps:
        z, dynamic, done, loss = step(z, dynamic, args)
        history.append(float(loss))
        if progress is not None:
            progress(history[-1])
        if not np.isfinite(history[-1]) or bool(done):
            break
        if stall and len(history) > stall and history[-1] > (1 - 1e-4) * history[-1 - stall]:
            break
    return z, history, len(history)


def fit(config, params: dict, target, w, keys: tuple[FitKey, ...], steps: int = 100,
        smooth: float = 1e-6, progress: Callable | None = None, solver: str = "auto",
        rate: float = ADAM_RATE) -> ImageFit:
    """Fit `keys` of a scene (`config`, `params`: the start) to `target`.

    **Arguments:**

    - `target (H, W, 3)`: display values in [0, 1] from the scene's camera.
    - `w (H, W)`: per-pixel weights (`weights`).
    - `keys`: from `fit_keys`.
    - `steps`: at most this many optimiser steps (for `"gn"`: tries, accepted or not).
    - `smooth`: the weight of the maps' total-variation prior (per map).
    - `progress`: called with the loss after each step.
    - `solver`: `"auto"` (Levenberg–Marquardt for scalars only; with maps the per-texel
      Gauss–Newton of `MAP_SOLVER_NOTE`, `"gn"`; Adam when Lafortune lobes are fitted with
      maps), or one of `"lm"`, `"gn"`, `"adam"`, `"lbfgs"`, `"ncg"` (for comparisons).
    - `rate`: Adam's step size.

    **Returns:** an `ImageFit`.
    """
    t0 = time.perf_counter()
    arrays = render.prepare(config).arrays
    target = jnp.asarray(target, jnp.float32)
    w = np.asarray(w, np.float64)
    if w.sum() <= 0:
        raise InputError("no pixel to fit: the mesh covers no pixel fully inside the mask")
    sqrt_w = jnp.asarray(np.sqrt(w / (3.0 * w.sum()))[..., None], jnp.float32)
    mask = np.asarray(arrays["mask"])
    start = dict(params)
    units, scales = {}, {}
    z0 = {}
    for fk in keys:
        if fk.kind == "map":
            units[fk.key] = _unit(fk, params)
            if units[fk.key] <= 0:
                raise InputError(f"'{fk.scalar}' is 0, and its map multiplies it; set it to "
                                 "the map's typical value (-D) to fit the map", key=fk.key)
            start[fk.scalar] = jnp.float32(units[fk.key])
            m0 = _start_map(config, params, fk, units[fk.key], arrays, mask)
            z0[fk.key] = jnp.asarray(_to_z(fk, m0, units[fk.key]), jnp.float32)
        elif fk.kind == "lafortune":
            z0[fk.key] = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32),
                                      _to_z(fk, params[fk.key]))
        else:
            z = _to_z(fk, params[fk.key])
            if fk.kind == "scalar":  # fitted as c z: see `_start_scale`
                scales[fk.key] = _start_scale(z)
                z = z * scales[fk.key]
            z0[fk.key] = jnp.asarray(z, jnp.float32)
    pairs = jnp.asarray(np.stack(_pairs(mask)), jnp.int32)
    maps = [fk for fk in keys if fk.kind == "map"]

    def unpack(z):
        p = dict(start)
        for fk in keys:
            zk = z[fk.key] / scales[fk.key] if fk.key in scales else z[fk.key]
            p[fk.key] = _from_z(fk, zk, units.get(fk.key, 1.0))
        return p

    def residual(z, args):
        image = render.render_prepared(config, unpack(z), args["arrays"])
        return (jnp.clip(image, 0.0, 1.0) - args["target"]) * args["sqrt_w"], None

    def loss(z, args):
        r, _ = residual(z, args)
        prior = sum(total_variation(unpack(z)[fk.key], args["pairs"]) for fk in maps)
        return jnp.sum(r * r) + smooth * prior, None

    lobes = any(fk.kind == "lafortune" for fk in keys)
    name = solver if solver != "auto" else (("adam" if lobes else "gn") if maps else "lm")
    args = {"arrays": arrays, "target": target, "sqrt_w": sqrt_w, "pairs": pairs}
    if name == "gn":
        if lobes or not maps:
            raise ValueError("the per-texel Gauss–Newton needs maps and no Lafortune lobes")
        z, history, n = _gauss_newton(config, keys, units, unpack, residual, loss, z0, args,
                                      smooth, steps, progress)
    else:
        if name == "lm":
            # |Δz| < 1e-4 of z (2.5e-5 of the range) and the loss changing by < 1e-4 of itself;
            # an absolute 1e-4 on the loss (a sum of squares of ~1e-3 on a face) once ended
            # a fit after its first, small step, far from the answer (skin.subject 44)
            s = optx.LevenbergMarquardt(rtol=1e-4, atol=1e-8)
            fn = residual
        else:
            fn = loss
            s = {"adam": lambda: optx.OptaxMinimiser(optax.adam(rate), rtol=0.0, atol=0.0),
                 "lbfgs": lambda: optx.LBFGS(rtol=0.0, atol=0.0),
                 "ncg": lambda: optx.NonlinearCG(rtol=0.0, atol=0.0)}[name]()
        z, history, n = _solve(s, fn, z0, args, steps, progress,
                               stall=5 if name == "lm" else None)
    fitted = unpack(z)
    image = np.asarray(render.render_prepared(config, fitted, arrays))
    r = (np.clip(image, 0, 1) - np.asarray(target)) * np.asarray(sqrt_w)
    values = {}
    for fk in keys:
        if fk.kind in ("scalar", "vector"):
            v = np.asarray(fitted[fk.key], np.float64)
            values[fk.key] = v.tolist() if v.ndim else float(v)
        elif fk.kind == "lafortune":
            values[fk.key] = jax.tree.map(np.asarray, fitted[fk.key])
    return ImageFit(fitted, values, history, float(np.sqrt(np.sum(r * r))), n,
                    time.perf_counter() - t0, name, image)


# --- the per-texel Gauss–Newton for maps -----------------------------------------------------

@functools.lru_cache(maxsize=4)
def view_matrix(config) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The linear map A from a texture-space colour to the image (`render.texture_to_view`:
    the padded texture's bilinear samples averaged over each pixel's supersamples) as a
    sparse matrix: `(pixel, texel, weight)` arrays, flat indices, duplicates summed (host
    NumPy, once per configuration)."""
    p = render.prepare(config)
    a = p.arrays
    pixel, texel, summed = pixel_entries(a["tex"], a["view_shaded"], a["pad"],
                                         np.asarray(a["mask"]).shape, p.view.wrap_x,
                                         config.supersample)
    keep = summed != 0
    return (pixel[keep].astype(np.int32), texel[keep].astype(np.int32),
            summed[keep].astype(np.float32))


def view_diagonal(config, d, view=None):
    """diag(Aᵀ diag(d) A) `(Ht, Wt, 3)`: per texel and channel, Σ_p A_pt² d_p, A the linear
    map from a texture-space colour to the image (`view_matrix`) and `d (H, W, 3)`
    per-pixel weights. Exact. `view`: `view_matrix(config)` as arrays, passed in by a jitted
    caller (else the matrix is a constant of the program: XLA spends tens of seconds at
    512² folding it)."""
    rows, cols, vals = (jnp.asarray(v) for v in (view_matrix(config) if view is None
                                                 else view))
    Ht, Wt = render.prepare(config).setup.mask.shape
    contrib = (vals * vals)[:, None] * d.reshape(-1, 3)[rows]
    return jax.ops.segment_sum(contrib, cols, num_segments=Ht * Wt).reshape(Ht, Wt, 3)


def blur_gain(config, arrays):
    """The SSS blur's share of a texel's own light that stays at the texel, as a root sum of
    squares: sqrt(Σ_t' w_t'←t²) per channel `(3,)` for the blur of a single texel at the
    mesh's most inland texel (1: no blur, or a blur under a texel). In a Gauss–Newton block
    the blurred part b of a texel's response then counts as sqrt(κ) b: its square κ b² is
    the blurred part's exact self-curvature, Σ_t' (w_t'←t b)²."""
    sp = config.spectral
    if sp is None or sp.sss is None:
        return jnp.ones(3, jnp.float32)
    from scipy.ndimage import distance_transform_edt

    from jaxskin import sss

    mask = np.asarray(arrays["mask"])
    inland = np.unravel_index(np.argmax(distance_transform_edt(mask)), mask.shape)
    delta = np.zeros((*mask.shape, 3), np.float32)
    delta[inland] = 1.0
    out = sss.blur(jnp.asarray(delta), render.prepare(config).texel_mm, arrays["mask"],
                   sp.sss, norm=arrays.get("sss_norm"), kernels=arrays.get("sss_kernels"))
    return jnp.sqrt(jnp.sum(out * out, axis=(0, 1)))


def texel_jacobian(config, params: dict, arrays, names, gain=None):
    """The texture-space colour `c (Ht, Wt, 3)` (`render.texture_colour`) and, per texel,
    its derivative with respect to that texel's value of each of the L maps `names` (keys
    into `params`): `(L, Ht, Wt, 3)`. A texel's colour depends on its own map values only
    (the SSS blur aside, below), so the Jacobian is diagonal over texels and one reverse-mode
    pass per colour channel (cotangent: that channel at every texel) gives every texel's
    derivatives for all L maps at once: 3 VJPs whatever L, sharing one forward pass. (Forward
    mode, one JVP per map along the whole map, gives the same numbers; measured at 512² on
    the makeup face: a JVP of the cosmetics colour costs ~4× the forward pass, a VJP ~2×, so
    three JVPs 10-13 s and the three VJPs 1.8 s.) The SSS blur spreads the part of a texel's
    response that enters the skin over its neighbours: its derivative is taken as `gain` ×
    identity (`blur_gain`, its own-texel root sum of squares); None: the blur's own
    transpose, which sums the shares the texel receives from its neighbours (right for a
    blur under a texel, wrong for a wide one when the surface and the blurred parts of a
    response have opposite signs and cancel)."""
    def colour(ms):
        return render.texture_colour(config, {**params, **dict(zip(names, ms, strict=True))},
                                     arrays, gain)

    c0, back = jax.vjp(colour, tuple(params[k] for k in names))
    per_channel = [jnp.stack(back(jnp.zeros_like(c0).at[..., c].set(1.0))[0]) for c in range(3)]
    return c0, jnp.stack(per_channel, axis=-1)


def texel_blocks(config, params: dict, arrays, names, tangents, d, gain=None, view=None):
    """Per texel, the L × L block of JᵀJ for L maps (`names`, keys into `params`), as
    `(Ht·Wt, L, L)`: Σ_channels D_tc a_l,tc a_m,tc with a_l = the texture-space colour's
    derivative along map l's `tangents[l] (Ht, Wt)` (`texel_jacobian` × the tangent) and
    D = `view_diagonal` of the per-pixel `d (H, W, 3)` = (∂ pixel / ∂ linear pixel)² ×
    weight (`view`: its argument). `gain`: the SSS blur's derivative (`texel_jacobian`).
    Exact without SSS (tests/test_fit_image.py); with it, the cross term between a texel's
    local and blurred parts uses sqrt(κ) for the kernel's centre weight. Also returns the
    texture colour `(Ht, Wt, 3)`."""
    c0, dc = texel_jacobian(config, params, arrays, names, gain)
    return _blocks(dc, tangents, view_diagonal(config, d, view)), c0


def _blocks(dc, tangents, D):
    """Σ_c D_tc a_l,tc a_m,tc, a_l = dc[l] × tangents[l]: `(Ht·Wt, L, L)`."""
    a = dc * jnp.stack(tangents)[..., None]
    B = jnp.einsum("thc,lthc,mthc->thlm", D, a, a)
    return B.reshape(-1, a.shape[0], a.shape[0])


def map_bounds(config, params: dict, names, w, sigma: float) -> dict:
    """How well an image can pin each texel of the maps `names` (keys in `params`, factor
    maps `(Ht, Wt)`), by the Cramér–Rao bound: the smallest standard deviation of an unbiased
    estimate of log(value) at each texel, from pixels with weights `w (H, W)` and Gaussian
    noise `sigma` in display values, the L maps at a texel estimated together (the inverse
    of its L × L Fisher block, `texel_blocks` with tangents m ∂/∂m) and their neighbours
    known. A texel whose bound is 0.025 has its value in the image to ±2.5 % (1σ); a
    saturated texel (an opaque lipstick) or one that matches the skin has a large bound;
    `inf` where no pixel sees it. Returns name → `(Ht, Wt)` relative bounds (float64)."""
    arrays = render.prepare(config).arrays
    p = dict(params)
    c0 = render.texture_colour(config, p, arrays)
    _, slope = _display_slope(config, p, arrays, c0)
    d = slope ** 2 * jnp.asarray(w, jnp.float32)[..., None] / sigma ** 2
    tangents = [jnp.asarray(p[k], jnp.float32) for k in names]
    B, _ = jax.jit(texel_blocks, static_argnums=(0, 3))(
        config, p, arrays, tuple(names), tangents, d, blur_gain(config, arrays),
        tuple(jnp.asarray(v) for v in view_matrix(config)))
    B = np.asarray(B, np.float64)
    L = len(names)
    diag = np.diagonal(B, axis1=1, axis2=2)
    # A map that is 0 at a texel (a layer absent there) or unseen carries no information
    # and has no log value: it leaves the texel's block (its bound: inf).
    absent = ~(diag > 1e-30 * max(float(diag.max()), 1e-300))
    keep = ~absent[:, :, None] & ~absent[:, None, :]
    Bk = np.where(keep, B, 0.0) + np.eye(L) * absent[:, None, :]
    sign, logdet = np.linalg.slogdet(Bk)
    scale = np.sum(np.log(np.where(absent, 1.0, diag)), axis=1)
    ok = (sign > 0) & (logdet - scale > np.log(1e-12))
    var = np.full(diag.shape, np.inf)
    var[ok] = np.diagonal(np.linalg.inv(Bk[ok]), axis1=1, axis2=2)
    var[absent] = np.inf
    shape = np.asarray(arrays["mask"]).shape
    return {k: np.sqrt(var[:, i]).reshape(shape) for i, k in enumerate(names)}


def _display_slope(config, params, arrays, c0):
    """The linear image of texture colour `c0` and d(display)/d(linear) per pixel: the
    exposure, the sRGB curve and the clip to [0, 1] (0 where clipped)."""
    lin = render.texture_to_view(config, arrays, c0)

    def display(x):
        return jnp.clip(render.encode_srgb(render.expose(x, params["camera.exposure"])),
                        0.0, 1.0)

    return jax.jvp(display, (lin,), (jnp.ones_like(lin),))


def pcg(matvec, b, precondition, rtol: float, steps: int):
    """Preconditioned conjugate gradients for `matvec(x) = b` (symmetric positive
    semidefinite), from 0, until ‖r‖ ≤ rtol ‖b‖ or `steps` iterations; a direction of zero
    curvature ends it (the iterate so far is kept). (`lineax.CG` with this preconditioner
    returned NaN at 256² in float32 where this does not; measured on the makeup face.)"""
    def dot(u, v):
        return jnp.sum(u * v)

    z = precondition(b)
    state = (jnp.zeros_like(b), b, z, dot(b, z), 0)
    limit = (rtol * jnp.sqrt(dot(b, b))) ** 2

    def cond(s):
        _, r, p, rz, i = s
        return (i < steps) & (dot(r, r) > limit) & (rz > 0)

    def body(s):
        x, r, p, rz, i = s
        Ap = matvec(p)
        pAp = dot(p, Ap)
        ok = pAp > 0
        alpha = jnp.where(ok, rz / jnp.where(ok, pAp, 1.0), 0.0)
        x = x + alpha * p
        r = r - alpha * Ap
        z = precondition(r)
        rz_new = jnp.where(ok, dot(r, z), 0.0)
        p = z + (rz_new / jnp.where(rz > 0, rz, 1.0)) * p
        return x, r, p, rz_new, i + 1

    return jax.lax.while_loop(cond, body, state)[0]


def _gauss_newton(config, keys, units, unpack, residual, loss, z0, args, smooth, steps,
                  progress):
    """Levenberg–Marquardt with a block-diagonal Gauss–Newton matrix (`MAP_SOLVER_NOTE`):
    per texel the L × L block of the maps (`texel_blocks`), the TV prior's curvature on
    its diagonal, one dense block for the scalars (forward-mode Jacobian through the whole
    render); no cross terms between blocks. The gradient is the exact one, from the reverse
    pass of the try that was accepted (its forward render is not repeated). Nielsen's
    damping update; a try whose loss does not fall is rejected (one forward render) and
    retried with more damping. Stops when the model's predicted decrease is below 1e-5
    of the loss, or after `steps` tries. `linearise` and `propose` are each compiled once
    (tests/test_fit_image.py). Returns z, the loss history, the number of tries."""
    maps = [fk for fk in keys if fk.kind == "map"]
    names = [fk.key for fk in maps]
    others = [fk.key for fk in keys if fk.kind != "map"]
    gain = blur_gain(config, args["arrays"])
    n_pairs = int(args["pairs"].shape[1])
    args = {**args, "view": tuple(jnp.asarray(v) for v in view_matrix(config))}

    def flat_others(z):
        return jax.flatten_util.ravel_pytree({k: z[k] for k in others})

    @jax.jit
    def linearise(z, f, back, args):
        g, = back(jnp.ones((), jnp.float32))
        p = unpack(z)
        tangents = []
        for fk in maps:  # dm/dz of the sigmoid: m (1 − m / top)
            m = p[fk.key]
            tangents.append(m * (1.0 - m / (fk.hi / units[fk.key])))
        c0, dc = texel_jacobian(config, p, args["arrays"], names, gain)
        _, slope = _display_slope(config, p, args["arrays"], c0)
        d = (slope * args["sqrt_w"]) ** 2
        B = 2.0 * _blocks(dc, tangents, view_diagonal(config, d, args["view"]))
        if others:
            x0, unflat = flat_others(z)

            def r_of(x):
                return residual({**z, **unflat(x)}, args)[0].reshape(-1)

            J = jax.jacfwd(r_of)(x0)
            S = 2.0 * J.T @ J
        else:
            S = jnp.zeros((0, 0), jnp.float32)
        return f, g, B, S

    def prior_of_maps(ms, args):  # the prior as a function of the maps' values m
        return smooth * sum(total_variation(m, args["pairs"]) for m in ms)

    @jax.jit
    def propose(z, g, B, S, lam, args):
        L = len(names)
        p = unpack(z)
        ms = [p[k] for k in names]
        shape = ms[0].shape
        t = jnp.stack([(m * (1.0 - m / (fk.hi / units[fk.key]))).reshape(-1)
                       for m, fk in zip(ms, maps, strict=True)], axis=-1)  # dm/dz (T, L)
        gm = jnp.stack([g[k].reshape(-1) for k in names], axis=-1)  # (T, L)
        # In units of the largest curvature (float32: the raw blocks are ~1e-7 at 256²).
        scale = jnp.maximum(jnp.max(jnp.diagonal(B, axis1=1, axis2=2)), 1e-30)
        Bs, gs_m = B / scale, gm / scale
        dB = jnp.diagonal(Bs, axis1=1, axis2=2)
        Bd = Bs + (lam * dB + 1e-6)[..., None] * jnp.eye(L, dtype=B.dtype)

        def hvp_prior(v):  # Jᵀ H_TV J v, J = dm/dz: the prior's Gauss–Newton part, exact
            tv = [(t[:, i] * v[:, i]).reshape(shape) for i in range(L)]
            _, h = jax.jvp(lambda m: jax.grad(prior_of_maps)(m, args), (ms,), (tv,))
            return jnp.stack([hi.reshape(-1) for hi in h], axis=-1) * t

        def matvec(v):  # (the data term's blocks, damped, + the prior's Hessian) v
            return jnp.einsum("tlm,tm->tl", Bd, v) + hvp_prior(v) / scale

        inv = jnp.linalg.inv(Bd + jax.vmap(jnp.diag)(B_prior_diag(t, ms, args) / scale))
        x = pcg(matvec, -gs_m, lambda v: jnp.einsum("tlm,tm->tl", inv, v), CG_RTOL, CG_STEPS)
        step = jnp.clip(x, -STEP_MAX, STEP_MAX)
        pred = -(jnp.sum(gm * step) + 0.5 * (jnp.einsum("tl,tlm,tm->", step, B, step)
                                             + jnp.sum(step * hvp_prior(step))))
        new = dict(z)
        for i, k in enumerate(names):
            new[k] = z[k] + step[:, i].reshape(shape)
        if others:
            x0, unflat = flat_others(z)
            gs, _ = flat_others(g)
            dS = jnp.diag(S)
            Sd = S + jnp.diag(lam * dS + 1e-6 * jnp.max(dS) + 1e-30)
            ds = -jnp.linalg.solve(Sd, gs)
            pred = pred - (gs @ ds + 0.5 * ds @ S @ ds)
            new.update(unflat(x0 + ds))
        # The loss at the try, with its reverse pass kept (`back`, a pytree): if the try is
        # accepted, the next `linearise` takes the gradient from it (no second forward).
        f_new, back = jax.vjp(lambda z: loss(z, args)[0], new)
        return new, f_new, pred, back

    def B_prior_diag(t, ms, args):  # the diagonal of the prior's Gauss–Newton matrix
        a, b = args["pairs"]
        out = []
        for i, m in enumerate(ms):
            flat = m.reshape(-1)
            dd = flat[a] - flat[b]
            c = PRIOR_EPS ** 2 / (dd * dd + PRIOR_EPS ** 2) ** 1.5 * smooth / n_pairs
            h = jnp.zeros_like(flat).at[a].add(c).at[b].add(c)
            out.append(h * t[:, i] ** 2)
        return jnp.stack(out, axis=-1)

    z, lam = z0, 1e-2
    clock = time.perf_counter()
    # The start's loss and reverse pass: `propose` with a zero gradient (a zero step), so
    # that `back` has the structure of every try's and `linearise` compiles once.
    n_others = flat_others(z)[0].size if others else 0
    _, f, _, back = propose(z, jax.tree.map(jnp.zeros_like, z),
                            jnp.zeros((z[names[0]].size, len(names), len(names)), jnp.float32),
                            jnp.zeros((n_others, n_others), jnp.float32), jnp.float32(lam),
                            args)
    f, g, B, S = linearise(z, f, back, args)
    nu, history = 2.0, []
    while len(history) < steps:
        if _DEBUG:
            jax.block_until_ready(B)
            t_lin, clock = time.perf_counter() - clock, time.perf_counter()
        new, f_try, pred, back = propose(z, g, B, S, jnp.float32(lam), args)
        f_new, pred, f0 = float(f_try), float(pred), float(f)
        rho = (f0 - f_new) / pred if pred > 0 else -1.0
        if _DEBUG:
            t_try, clock = time.perf_counter() - clock, time.perf_counter()
            print(f"gn: f {f0:.4e} try {f_new:.4e} predicted {pred:.3e} λ {lam:.2e} "
                  f"(linearise {t_lin:.2f} s, try {t_try:.2f} s)", flush=True)
        if np.isfinite(f_new) and f_new < f0 and rho > 0:
            z = new
            lam *= max(1.0 / 3.0, 1.0 - (2.0 * rho - 1.0) ** 3)
            nu = 2.0
            history.append(f_new)
            if progress is not None:
                progress(f_new)
            if pred < GN_RTOL * f_new:
                break
            f, g, B, S = linearise(z, f_try, back, args)
        else:
            lam *= nu
            nu *= 2.0
            history.append(f0)
            if progress is not None:
                progress(f0)
            if lam > 1e8:
                break
    return z, history, len(history)


def _start_map(config, params, fk: FitKey, unit: float, arrays, mask):
    """A map's start `(H, W)`, in units of `unit`: the scene's own map (its image or
    regions) × its scalar, with off-mesh texels at the mesh's mean."""
    texels = np.asarray(arrays["texels"])
    H, W = mask.shape
    if fk.key in SKIN_MAPS:
        own = arrays.get(render.map_cover(fk.key))
    else:
        names = [layer.name for layer in config.spectral.layers]
        own = arrays["cover"][names.index(fk.key.split(".")[1])]
    on_mesh = np.ones(len(texels)) if own is None else np.asarray(own, np.float64)
    on_mesh = on_mesh * float(params[fk.scalar]) / unit
    out = np.full(H * W, on_mesh.mean() if on_mesh.size else 0.0)
    out[texels] = on_mesh
    return out.reshape(H, W)


def map_image(fitted: ImageFit, fk: FitKey, mask) -> tuple[np.ndarray, float]:
    """A fitted map as the scene holds it: the greyscale image `(H, W)` in [0, 1] (its
    largest texel on the mesh is 1; 0 off the mesh) and the scalar it multiplies."""
    m = np.asarray(fitted.params[fk.key], np.float64)
    scalar = float(fitted.params[fk.scalar])
    top = float(m[mask].max()) if mask.any() else 0.0
    if top <= 0:
        return np.zeros_like(m), scalar
    return np.where(mask, np.clip(m / top, 0.0, 1.0), 0.0), scalar * top


def write_report(result: ImageFit, target, w, maps: dict, path, title: str = "") -> None:
    """The report PNG: target, fit, |residual| heat map, loss against step, and each fitted
    map (`maps`: key → (values `(H, W)` in the scalar's units, texture mask, unit name))."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt


    ncol = 4
    rows = 1 + -(-len(maps) // ncol)
    fig, axes = plt.subplots(rows, ncol, figsize=(4 * ncol, 3.9 * rows), squeeze=False,
                             constrained_layout=True)
    fit_image = np.clip(result.image, 0, 1)
    axes[0, 0].imshow(np.clip(target, 0, 1))
    axes[0, 0].set_title("target")
    axes[0, 1].imshow(fit_image)
    axes[0, 1].set_title(f"fit ({result.solver}, {result.steps} steps, {result.seconds:.0f} s)")
    err = np.abs(fit_image - np.asarray(target)).mean(axis=-1)
    err = np.where(np.asarray(w) > 0, err, np.nan)
    im = axes[0, 2].imshow(err, cmap="inferno", vmin=0)
    axes[0, 2].set_title(f"|fit − target| (RMS {result.rms:.4f})")
    fig.colorbar(im, ax=axes[0, 2], shrink=0.8)
    ax = axes[0, 3]
    ax.semilogy(np.arange(1, len(result.history) + 1), result.history)
    finite = [v for v in result.history if np.isfinite(v) and v > 0]
    if finite and max(finite) < 10 * min(finite):  # at least a decade shown: a flat loss
        ax.set_ylim(min(finite) / 4, max(finite) * 4)  # had every tick "4.52176×10⁻⁴" (a trial)
    ax.set_xlabel("step")
    ax.set_ylabel("loss")
    ax.set_title("loss")
    ax.grid(alpha=0.3)
    for a in axes[0, :3]:
        a.set_axis_off()
    titles = []
    for i, (key, (values, tmask, unit)) in enumerate(maps.items()):
        a = axes[1 + i // ncol, i % ncol]
        im = a.imshow(np.where(tmask, values, np.nan), cmap="viridis")
        # Key and unit on two lines: on one, "skin.melanin_fraction_map (skin.melanin_fraction)"
        # was wider than its panel and cut off at the figure's left edge.
        titles.append((a, a.set_title(f"{key}\n({unit})")))
        a.set_axis_off()
        fig.colorbar(im, ax=a, shrink=0.8)
    for j in range(len(maps), (rows - 1) * ncol):
        axes[1 + j // ncol, j % ncol].set_axis_off()
    if title:
        fig.suptitle(title)
    if titles:  # a line still wider than its panel (a layer's name is the user's): smaller
        fig.canvas.draw()  # lays the panels out, so their widths are known
        for a, t in titles:
            over = t.get_window_extent().width / a.get_window_extent().width
            if over > 1:
                t.set_fontsize(t.get_fontsize() / over)
    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png", dpi=90)
    plt.close(fig)


# --- the command ----------------------------------------------------------------------------

def _jpeg_note(path) -> str | None:
    """"a JPEG (lossy, chroma subsampled 4:2:0)" and the like for a JPEG file, else None."""
    try:
        with open(path, "rb") as f:
            if f.read(3) != b"\xff\xd8\xff":
                return None
        from PIL import Image, JpegImagePlugin

        with Image.open(path) as im:
            sampling = JpegImagePlugin.get_sampling(im)
    except (OSError, ValueError, ImportError):
        return "a JPEG (lossy)"
    kind = {0: "4:4:4", 1: "4:2:2", 2: "4:2:0"}.get(sampling)
    return "a JPEG (lossy" + (f", chroma subsampled {kind})" if sampling in (1, 2) else ")")


def run_command(args, run) -> int:
    """`jaxskin fit-image` (the CLI's body): check everything, fit, write DIR/<name>.toml,
    the maps as 16-bit PNGs and DIR/<name>_fit.png. `run`: the CLI's record of what is
    written."""
    from tqdm import tqdm

    from jaxskin import cli, maps
    from jaxskin.checks import check_scene, reading
    from jaxskin.outputs import Outputs, check_name
    from jaxskin.scene import load_scene, scene_toml

    outputs = Outputs(args.output)
    with reading(args.scene):
        scene = load_scene(args.scene, args.overrides, flag="-D")
    keys = fit_keys(scene, args.fit)
    has_maps = any(fk.kind == "map" for fk in keys)
    solver = getattr(args, "solver", "auto")
    if solver == "gn" and (not has_maps or any(fk.kind == "lafortune" for fk in keys)):
        raise InputError("the Gauss-Newton solver is for maps (and not with "
                         "material.lafortune); use --solver auto", "--solver")
    if not has_maps:
        solver = "auto"
    config = scene.config
    height, width = config.image_height or config.image, config.image
    target, target_alpha = maps.read_image(args.target, "image")
    if target.shape[:2] != (height, width):
        raise InputError(f"the target is {target.shape[1]}x{target.shape[0]} pixels, the "
                         f"scene's camera {width}x{height} (camera.size, camera.height; set "
                         "them with -D)", args.target)
    mask = None
    if args.mask is not None:
        rgb, _ = maps.read_image(args.mask, "image")
        if rgb.shape[:2] != (height, width):
            raise InputError(f"the mask is {rgb.shape[1]}x{rgb.shape[0]} pixels, the target "
                             f"{width}x{height}", args.mask)
        mask = rgb.mean(axis=-1)
    outputs.inputs += [Path(p) for p in check_scene(scene, 1, args.overrides)]
    outputs.inputs += [Path(p) for p in (args.target, args.mask) if p is not None]
    name = check_name(scene.name, scene.source)
    toml_path = outputs.plan(f"{name}.toml", "the fitted scene")
    report_path = outputs.plan(f"{name}_fit.png", "the report")
    map_paths = {fk.key: outputs.plan(f"{name}_{fk.key}.png", fk.key)
                 for fk in keys if fk.kind == "map"}
    brdf_path = (outputs.plan(f"{name}_brdf.json", "the fitted lobes")
                 if any(fk.kind == "lafortune" for fk in keys) else None)
    params = scene.params
    w = weights(config, params, target_alpha, mask)
    if w.sum() <= 0:
        opaque = target_alpha is None or bool(np.any(np.asarray(target_alpha) > 0))
        raise InputError("no pixel to fit: " + (
            "the target's alpha is 0 everywhere (a fully transparent image)" if not opaque else
            "the mesh covers no pixel fully" + (" inside the mask" if mask is not None else "")
            + (" where the target's alpha is above 0" if target_alpha is not None else "")),
            args.mask or args.target)
    fitted = np.asarray(target)[w > 0]
    if np.all(fitted.max(axis=-1) == fitted.min(axis=-1)):
        warnings.warn(f"{args.target}: the target is greyscale (R = G = B at every fitted "
                      "pixel) and the render is in colour: the fit can only match its "
                      "brightness, so skin and cosmetic colour keys come out wrong; fit a "
                      "colour photograph", stacklevel=1)
    lossy = _jpeg_note(args.target)
    if lossy:
        warnings.warn(f"{args.target}: {lossy}: its colours are shifted at the scale of a few "
                      "pixels, which biases the colour keys (blood came out 0.16 for a true "
                      "0.3 at quality 95, 4:2:0) while the fit looks good; give a PNG or TIFF",
                      stacklevel=1)
    run.outputs.append(outputs)
    run.stage = "fitting"
    print(f"fitting {', '.join(k.key for k in keys)} to {args.target} "
          f"({width}x{height}, {int((w > 0).sum())} pixels)", flush=True)
    with cluster.pool(args.cluster) as pool:
        if pool.client is None:  # here: a progress bar over the steps, with the loss
            with tqdm(total=args.steps, desc="fit-image", unit="step", disable=None) as bar:
                def progress(loss):
                    bar.set_postfix(loss=f"{loss:.3e}", refresh=False)
                    bar.update(1)

                result = fit(config, params, target, w, keys, steps=args.steps,
                             smooth=args.smooth, progress=progress, solver=solver)
        else:  # the fit is one unit of work: one task on a worker (a GPU one, say)
            unit = functools.partial(fit, config, params, target, w, keys, steps=args.steps,
                                     smooth=args.smooth, solver=solver)
            (result, _), = pool.map(lambda _: unit(), [None], desc="fit-image", unit="fit")
    run.stage = "writing"
    tmask = np.asarray(render.prepare(config).arrays["mask"])
    values = dict(result.values)
    if "light.direction" in values:  # free while fitting (the renderer normalises it)
        d = np.asarray(values["light.direction"], np.float64)
        values["light.direction"] = d / np.linalg.norm(d)
    if brdf_path is not None:
        from jaxskin.formats import write_lafortune

        write_lafortune(values.pop("material.lafortune"), brdf_path,
                        fit={"source": Path(args.target).name, "rms": result.rms})
        outputs.done(brdf_path)
        values["material.brdf"] = brdf_path.name
    images, shown = {}, {}
    for fk in keys:
        if fk.kind != "map":
            continue
        grey, scalar = map_image(result, fk, tmask)
        hi = _schema(fk.scalar).hi
        if scalar > hi:
            warnings.warn(f"{fk.key}: the fitted map's largest value {scalar:g} is beyond "
                          f"{fk.scalar}'s range (≤ {hi:g}); written as {hi:g}", stacklevel=1)
            grey, scalar = grey * scalar / hi, hi
        values[fk.scalar] = scalar
        maps.write_grey16(grey, map_paths[fk.key])
        outputs.done(map_paths[fk.key])
        images[fk.key] = map_paths[fk.key].name
        shown[fk.key] = (grey * scalar, tmask, "mm" if fk.scalar.endswith("_mm") else
                         fk.scalar)
    comment = (f"Fitted by jaxskin fit-image to {args.target} ({result.solver}, "
               f"{result.steps} steps, RMS {result.rms:.4g})\nfrom {scene.source}; fitted: "
               + ", ".join(k.key for k in keys))
    with atomic_write(toml_path, "w") as fh:
        fh.write(scene_toml(scene, values, images, comment))
    outputs.done(toml_path)
    write_report(result, target, w, shown, report_path,
                 f"{scene.name}: fit-image {', '.join(k.key for k in keys)}")
    outputs.done(report_path)
    print(f"{'key':<28} {'start':>12} {'fitted':>12}")
    for fk in keys:
        if fk.kind == "lafortune":
            print(f"{fk.key:<28} {'(lobes)':>12} {brdf_path.name:>12}")
        elif fk.kind != "map":
            print(f"{fk.key:<28} {_fmt(params[fk.key]):>12} {_fmt(values[fk.key]):>12}")
        else:
            print(f"{fk.key:<28} {'(map)':>12} {'× ' + _fmt(values[fk.scalar]):>12}")
    sigma = noise_sigma(target, w)
    print(f"RMS difference {result.rms:.4g} (display values) after {result.steps} steps "
          f"({result.seconds:.1f} s)"
          + ("" if sigma is None else f"; the target's noise estimate {sigma:.2g}"))
    floor = None if sigma is None else max(sigma, 0.5 / 255)  # 8-bit rounding at least
    if floor is not None and result.rms > ABOVE_NOISE * floor:
        limit = (f"; it stopped at the --steps limit ({args.steps})"
                 if result.steps >= args.steps else "")
        noise = (f"the target's noise estimate ({sigma:.2g}, from its pixel-to-pixel "
                 "variation, texture included)" if sigma >= floor else
                 f"half an 8-bit step ({floor:.2g}; the target varies less than that from "
                 "pixel to pixel, a flat colour?)")
        warnings.warn(f"the fit ends at RMS {result.rms:.3g}, {result.rms / floor:.0f}x {noise}"
                      f"{limit}: the fitted keys do not explain the image; fit more keys, "
                      "start closer (-D KEY=VALUE) or allow more --steps, and see the "
                      "residual in the report", stacklevel=1)
    cli._print_written(outputs)
    return 0


def _fmt(v) -> str:
    a = np.asarray(v, np.float64)
    return f"{float(a):.4g}" if a.ndim == 0 else "[" + ", ".join(f"{x:.3g}" for x in a) + "]"
