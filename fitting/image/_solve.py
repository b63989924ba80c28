"""The fit: the optimistix solvers stepped one iteration at a time, and its result."""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import optax
import optimistix as optx

from jaxskin import render
from jaxskin.io import InputError

from ._keys import FitKey, from_z, map_unit, start_scale, to_z
from ._loss import texel_pairs, total_variation
from ._texel import gauss_newton, start_map

ADAM_RATE = 0.3  # per step, in the transformed (log-like) coordinates: ~35 % at most


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


def _solve_loop(solver, fn, z0, args, steps: int, progress: Callable | None,
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
            units[fk.key] = map_unit(fk, params)
            if units[fk.key] <= 0:
                raise InputError(f"'{fk.scalar}' is 0, and its map multiplies it; set it to "
                                 "the map's typical value (-D) to fit the map", key=fk.key)
            start[fk.scalar] = jnp.float32(units[fk.key])
            m0 = start_map(config, params, fk, units[fk.key], arrays, mask)
            z0[fk.key] = jnp.asarray(to_z(fk, m0, units[fk.key]), jnp.float32)
        elif fk.kind == "lafortune":
            z0[fk.key] = jax.tree.map(lambda a: jnp.asarray(a, jnp.float32),
                                      to_z(fk, params[fk.key]))
        else:
            z = to_z(fk, params[fk.key])
            if fk.kind == "scalar":  # fitted as c z: see `start_scale`
                scales[fk.key] = start_scale(z)
                z = z * scales[fk.key]
            z0[fk.key] = jnp.asarray(z, jnp.float32)
    pairs = jnp.asarray(np.stack(texel_pairs(mask)), jnp.int32)
    maps = [fk for fk in keys if fk.kind == "map"]

    def unpack(z):
        p = dict(start)
        for fk in keys:
            zk = z[fk.key] / scales[fk.key] if fk.key in scales else z[fk.key]
            p[fk.key] = from_z(fk, zk, units.get(fk.key, 1.0))
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
        z, history, n = gauss_newton(config, keys, units, unpack, residual, loss, z0, args,
                                     smooth, steps, progress)
    else:
        if name == "lm":
            # |Δz| < 1e-4 of z (2.5e-5 of the range) and the loss changing by < 1e-4 of itself;
            # the absolute tolerance tiny: the loss is a sum of squares of ~1e-3 on a face, and
            # an absolute 1e-4 ends a fit after its first, small step, far from the answer
            s = optx.LevenbergMarquardt(rtol=1e-4, atol=1e-8)
            fn = residual
        else:
            fn = loss
            s = {"adam": lambda: optx.OptaxMinimiser(optax.adam(rate), rtol=0.0, atol=0.0),
                 "lbfgs": lambda: optx.LBFGS(rtol=0.0, atol=0.0),
                 "ncg": lambda: optx.NonlinearCG(rtol=0.0, atol=0.0)}[name]()
        z, history, n = _solve_loop(s, fn, z0, args, steps, progress,
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


def map_image(fitted: ImageFit, fk: FitKey, mask) -> tuple[np.ndarray, float]:
    """A fitted map as the scene holds it: the greyscale image `(H, W)` in [0, 1] (its
    largest texel on the mesh is 1; 0 off the mesh) and the scalar it multiplies."""
    m = np.asarray(fitted.params[fk.key], np.float64)
    scalar = float(fitted.params[fk.scalar])
    top = float(m[mask].max()) if mask.any() else 0.0
    if top <= 0:
        return np.zeros_like(m), scalar
    return np.where(mask, np.clip(m / top, 0.0, 1.0), 0.0), scalar * top
