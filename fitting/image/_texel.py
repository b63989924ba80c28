"""The maps' per-texel Gauss–Newton (`MAP_SOLVER_NOTE`): the view map's matrix, the per-texel
Jacobian and blocks of JᵀJ, their preconditioned CG, and the Cramér–Rao bounds of a map."""

from __future__ import annotations

import functools
import time

import jax
import jax.flatten_util
import jax.numpy as jnp
import numpy as np

from jaxskin import render, skin_texels
from jaxskin.scene import SKIN_MAPS
from jaxskin.view import pixel_entries

from ._keys import FitKey
from ._loss import PRIOR_EPS, total_variation

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
    "render per inner iteration; so the step is our own, in the loop `_solve_loop` runs "
    "for the optimistix solvers. Measured against Adam (benchmarks/RESULTS.md, 'fit-image'): see "
    "there. L-BFGS and NonlinearCG (optimistix, float32) never left the start's loss in "
    "150 steps on the makeup face (their line searches rejected every step).")
STEP_MAX = 1.0  # the Gauss–Newton step's largest change of a coordinate (e ≈ 2.7× a texel)
GN_RTOL = 1e-5  # stop when the Gauss–Newton model predicts less than this share of the loss
# The inner conjugate-gradient solve of each Gauss–Newton step: an inexact Newton step, to
# 0.1 of the right-hand side (1-2 iterations for the predicted decrease of a tight solve, to
# 0.3 %, where 1e-3 runs all 100; benchmarks/RESULTS.md, 'fit-image').
CG_RTOL = 0.1
CG_STEPS = 100  # … and its most iterations (each one texture-space prior HVP: cheap)
_DEBUG = bool(__import__("os").environ.get("JAXSKIN_FIT_DEBUG"))

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
    texel_mm = render.prepare(config).texel_mm

    @jax.jit  # one program: op by op, each of the blur's operations compiled its own
    def gain(delta, mask, norm, kernels):
        out = sss.blur(delta, texel_mm, mask, sp.sss, norm=norm, kernels=kernels)
        return jnp.sqrt(jnp.sum(out * out, axis=(0, 1)))

    return gain(jnp.asarray(delta), arrays["mask"], arrays.get("sss_norm"),
                arrays.get("sss_kernels"))


def texel_jacobian(config, params: dict, arrays, names, gain=None):
    """The texture-space colour `c (Ht, Wt, 3)` (`render.texture_colour`) and, per texel,
    its derivative with respect to that texel's value of each of the L maps `names` (keys
    into `params`): `(L, Ht, Wt, 3)`. A texel's colour depends on its own map values only
    (the SSS blur aside, below), so the Jacobian is diagonal over texels and one reverse-mode
    pass per colour channel (cotangent: that channel at every texel) gives every texel's
    derivatives for all L maps at once: 3 VJPs whatever L, sharing one forward pass. (Forward
    mode, one JVP per map along the whole map, gives the same numbers at a higher cost: a
    JVP of the cosmetics colour costs ~4× the forward pass, a VJP ~2×; benchmarks/RESULTS.md,
    'fit-image'.) The SSS blur spreads the part of a texel's
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
    tangents = [jnp.asarray(p[k], jnp.float32) for k in names]

    @jax.jit  # one program (op by op, the shading compiled hundreds of small ones)
    def blocks(p, arrays, w, tangents, gain, view):
        c0 = render.texture_colour(config, p, arrays)
        _, slope = display_slope(config, p, arrays, c0)
        d = slope ** 2 * w[..., None] / sigma ** 2
        return texel_blocks(config, p, arrays, tuple(names), tangents, d, gain, view)[0]

    B = blocks(p, arrays, jnp.asarray(w, jnp.float32), tangents, blur_gain(config, arrays),
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


def display_slope(config, params, arrays, c0):
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
    curvature ends it (the iterate so far is kept). (Not `lineax.CG`: with this
    preconditioner it returns NaN in float32 at 256² on the makeup face, where this does
    not.)"""
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


def gauss_newton(config, keys, units, unpack, residual, loss, z0, args, smooth, steps,
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
    linearise = _linearise(config, maps, units, others, unpack, residual, gain)
    propose = _propose(maps, units, others, unpack, loss, smooth, n_pairs)
    z, lam = z0, 1e-2
    clock = time.perf_counter()
    # The start's loss and reverse pass: `propose` with a zero gradient (a zero step), so
    # that `back` has the structure of every try's and `linearise` compiles once.
    n_others = _flat_others(z, others)[0].size if others else 0
    _, f, _, back = propose(z, jax.tree.map(jnp.zeros_like, z),
                            jnp.zeros((z[names[0]].size, len(names), len(names)), jnp.float32),
                            jnp.zeros((n_others, n_others), jnp.float32), jnp.float32(lam),
                            args)
    f, g, B, S = linearise(z, f, back, args)
    return _damped_tries(linearise, propose, z, lam, f, g, B, S, args, steps, progress, clock)


def _flat_others(z, others):
    """The scalars' and vectors' coordinates `others` of `z` as one flat vector, and its
    unflattening."""
    return jax.flatten_util.ravel_pytree({k: z[k] for k in others})


def _linearise(config, maps, units, others, unpack, residual, gain):
    """The jitted `linearise(z, f, back, args) -> (f, g, B, S)`: at `z`, whose loss `f` and
    reverse pass `back` the accepted try left, the gradient `g`, the maps' per-texel blocks
    `B (Ht·Wt, L, L)` of the data term's Gauss–Newton matrix (`texel_blocks`' parts, with the
    sigmoid's tangents) and the scalars' dense block `S` (forward-mode Jacobian of the
    residual through the whole render)."""
    names = [fk.key for fk in maps]

    @jax.jit
    def linearise(z, f, back, args):
        g, = back(jnp.ones((), jnp.float32))
        p = unpack(z)
        tangents = []
        for fk in maps:  # dm/dz of the sigmoid: m (1 − m / top)
            m = p[fk.key]
            tangents.append(m * (1.0 - m / (fk.hi / units[fk.key])))
        c0, dc = texel_jacobian(config, p, args["arrays"], names, gain)
        _, slope = display_slope(config, p, args["arrays"], c0)
        d = (slope * args["sqrt_w"]) ** 2
        B = 2.0 * _blocks(dc, tangents, view_diagonal(config, d, args["view"]))
        if others:
            x0, unflat = _flat_others(z, others)

            def r_of(x):
                return residual({**z, **unflat(x)}, args)[0].reshape(-1)

            J = jax.jacfwd(r_of)(x0)
            S = 2.0 * J.T @ J
        else:
            S = jnp.zeros((0, 0), jnp.float32)
        return f, g, B, S

    return linearise


def _propose(maps, units, others, unpack, loss, smooth, n_pairs):
    """The jitted `propose(z, g, B, S, lam, args) -> (new, f_new, pred, back)`: the damped
    step from `z` (gradient `g`, blocks `B` and `S` from `linearise`, damping `lam`), the
    try `new`, its loss `f_new`, the decrease the model predicts `pred`, and the try's
    reverse pass `back` (a pytree)."""
    names = [fk.key for fk in maps]

    @jax.jit
    def propose(z, g, B, S, lam, args):
        p = unpack(z)
        ms = [p[k] for k in names]
        shape = ms[0].shape
        t = jnp.stack([(m * (1.0 - m / (fk.hi / units[fk.key]))).reshape(-1)
                       for m, fk in zip(ms, maps, strict=True)], axis=-1)  # dm/dz (T, L)
        gm = jnp.stack([g[k].reshape(-1) for k in names], axis=-1)  # (T, L)
        step, pred = _map_step(ms, t, gm, B, lam, args, smooth, n_pairs)
        new = dict(z)
        for i, k in enumerate(names):
            new[k] = z[k] + step[:, i].reshape(shape)
        if others:
            x0, unflat = _flat_others(z, others)
            gs, _ = _flat_others(g, others)
            ds = _scalar_step(S, gs, lam)
            pred = pred - (gs @ ds + 0.5 * ds @ S @ ds)
            new.update(unflat(x0 + ds))
        # The loss at the try, with its reverse pass kept (`back`, a pytree): if the try is
        # accepted, the next `linearise` takes the gradient from it (no second forward).
        f_new, back = jax.vjp(lambda z: loss(z, args)[0], new)
        return new, f_new, pred, back

    return propose


def _map_step(ms, t, gm, B, lam, args, smooth, n_pairs):
    """The maps' damped step `(T, L)` in their coordinates z and the decrease its model
    predicts: the data term's blocks `B` damped by `lam` plus the TV prior's exact
    Gauss–Newton matrix, solved by CG (`pcg`) preconditioned by the inverse blocks with the
    prior's diagonal; each coordinate's change clipped to `STEP_MAX`. `ms`: the maps'
    values, `t (T, L)` their dm/dz, `gm (T, L)` the gradient."""
    L = len(ms)
    shape = ms[0].shape

    def prior_of_maps(ms, args):  # the prior as a function of the maps' values m
        return smooth * sum(total_variation(m, args["pairs"]) for m in ms)

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

    prior_diag = _prior_diagonal(t, ms, args["pairs"], smooth, n_pairs)
    inv = jnp.linalg.inv(Bd + jax.vmap(jnp.diag)(prior_diag / scale))
    x = pcg(matvec, -gs_m, lambda v: jnp.einsum("tlm,tm->tl", inv, v), CG_RTOL, CG_STEPS)
    step = jnp.clip(x, -STEP_MAX, STEP_MAX)
    pred = -(jnp.sum(gm * step) + 0.5 * (jnp.einsum("tl,tlm,tm->", step, B, step)
                                         + jnp.sum(step * hvp_prior(step))))
    return step, pred


def _prior_diagonal(t, ms, pairs, smooth, n_pairs):
    """The diagonal `(T, L)` of the TV prior's Gauss–Newton matrix in the coordinates z
    (`t`: dm/dz), for the preconditioner."""
    a, b = pairs
    out = []
    for i, m in enumerate(ms):
        flat = m.reshape(-1)
        dd = flat[a] - flat[b]
        c = PRIOR_EPS ** 2 / (dd * dd + PRIOR_EPS ** 2) ** 1.5 * smooth / n_pairs
        h = jnp.zeros_like(flat).at[a].add(c).at[b].add(c)
        out.append(h * t[:, i] ** 2)
    return jnp.stack(out, axis=-1)


def _scalar_step(S, gs, lam):
    """The scalars' damped Levenberg–Marquardt step: `S` (their dense block) with `lam`
    times its diagonal added, solved for the gradient `gs`."""
    dS = jnp.diag(S)
    Sd = S + jnp.diag(lam * dS + 1e-6 * jnp.max(dS) + 1e-30)
    return -jnp.linalg.solve(Sd, gs)


def _damped_tries(linearise, propose, z, lam, f, g, B, S, args, steps, progress, clock):
    """The tries from `z` (loss `f`, linearised as `g, B, S`, damping `lam`): a try whose
    loss falls, as its model predicted, is accepted and relinearised (Nielsen's update of
    `lam`); one that does not is rejected and retried with more damping. Returns z, the
    loss history (per try) and the number of tries."""
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


def start_map(config, params, fk: FitKey, unit: float, arrays, mask):
    """A map's start `(H, W)`, in units of `unit`: the scene's own map (its image or
    regions) × its scalar, with off-mesh texels at the mesh's mean."""
    texels = np.asarray(arrays["texels"])
    H, W = mask.shape
    if fk.key in SKIN_MAPS:
        own = arrays.get(skin_texels.map_cover(fk.key))
    else:
        names = [layer.name for layer in config.spectral.layers]
        own = arrays["cover"][names.index(fk.key.split(".")[1])]
    on_mesh = np.ones(len(texels)) if own is None else np.asarray(own, np.float64)
    on_mesh = on_mesh * float(params[fk.scalar]) / unit
    out = np.full(H * W, on_mesh.mean() if on_mesh.size else 0.0)
    out[texels] = on_mesh
    return out.reshape(H, W)
