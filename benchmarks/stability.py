"""Numerical stability of every differentiable stage on stiff and extreme inputs.

    python benchmarks/stability.py           # 1.5 minutes, 10 GB; the `stability` section

For each stage, a grid of extreme inputs (K/S from 0 to 1e6, S·X from 0 to 1e4, thickness 0,
grazing light and view, n_z → 0, shininess and lobe exponents to 1e4, steep bumps, furrows
at |d| = 0 and 2, the cosmetics stages, texture sizes 64² to 4096²) is run in float32 and
float64: the count of non-finite values and of non-finite gradients (both must
be 0; tests/test_stability.py fails otherwise) and the largest float32 error against float64
(absolute, on outputs that live in [0, 1] or are unit vectors).
"""

from __future__ import annotations

import functools
import itertools
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from jaxskin import bump, km, wrinkles
from jaxskin.shading import blinn, kelemen, lafortune


def _grid(*axes):
    return [np.array(c, np.float64) for c in zip(*itertools.product(*axes), strict=True)]


def _unit(v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


def _directions(thetas_deg):
    t = np.radians(np.asarray(thetas_deg, np.float64))
    return np.stack([np.sin(t), np.zeros_like(t), np.cos(t)], -1)


def cases(large: bool = False):
    """(stage, function of float arrays -> array, inputs as float64 arrays). `large` adds
    the 4096² bump map and the 2048² blur (about 10 GB and a minute and a half: the
    benchmark runs them, the test suite does not)."""
    out = []
    S, ratio, SX = _grid([1e-3, 1.0, 1e3], [0.0, 1e-9, 1e-3, 1.0, 1e3, 1e6],
                         [0.0, 1e-6, 1e-3, 1.0, 1e2, 1e4])
    out.append(("km.layer (K/S 0–1e6, S·X 0–1e4)",
                lambda s, k, x: jnp.stack(km.layer(s, k, x)), [S, ratio * S, SX / S]))
    S2, ratio2 = _grid([1e-3, 1.0, 1e3], [1e-9, 1e-3, 1.0, 1e3, 1e6])
    out.append(("km.r_inf (K/S 1e-9–1e6)", km.r_inf, [S2, ratio2 * S2]))

    def stack_over(s, k, x):  # layers along the first axis, as km.stack takes them
        # (written (cases, 3) before, it stacked 108 layers over 3 cases: 6,135 operations
        # in the gradient, two minutes to compile)
        column = jnp.array([[1.0], [5.0], [0.5]], s.dtype)
        st = km.stack(*km.layer(s * column, k * column[::-1], x * jnp.ones_like(column)))
        return km.over(st.R, st.T, 0.45, st.R_back)

    out.append(("km.stack + over (3 layers, thickness 0–huge)", stack_over,
                [S, ratio * S, SX / S]))

    light = _directions([0, 30, 60, 85, 89.9, 89.9999, 90.0])
    normals = _unit([[0, 0, 1], [0.3, 0.1, 0.95], [1, 0, 1e-7], [0, 1, 0]])
    L, N = (np.repeat(light, len(normals), 0), np.tile(normals, (len(light), 1)))
    V = np.broadcast_to([0.0, 0.0, 1.0], L.shape).copy()
    for shininess in (1.0, 100.0, 1e4):
        out.append((f"blinn.shade (grazing light, n_z → 0, shininess {shininess:g})",
                    lambda n, l_, v, sh=shininess: blinn.shade(n, l_, v, 0.2, 0.5, 0.2, sh),
                    [N, L, V]))
    def lafortune_shade(n, l_, v, scale):
        p = lafortune.skin(n.dtype)  # built in the run's own precision
        return lafortune.shade(lafortune.Lafortune(p.diffuse, p.Cxy, p.Cz, p.n * scale), n,
                               l_, v)

    for scale in (1.0, 100.0):
        out.append((f"lafortune.shade (grazing, exponents × {scale:g})",
                    lambda n, l_, v, sc=scale: lafortune_shade(n, l_, v, sc),
                    [N, L, _unit(V + [0.01, 0, 0])]))
    V_opposite = -L  # includes L = −V: no half vector
    for m in (0.05, 0.3, 1.0):
        out.append((f"kelemen.specular (grazing, L = −V, roughness {m:g})",
                    lambda n, l_, v, mm=m: kelemen.specular(n, l_, v, mm, 0.18),
                    [N, L, np.where(np.arange(len(L))[:, None] % 3 == 0, V_opposite, V)]))
    rng = np.random.default_rng(0)
    nmap = _unit(np.concatenate([np.tile([0.0, 0.0, 1.0], (4, 8, 1)),
                                 np.tile([1.0, 0.0, 1e-7], (4, 8, 1))], 0)
                 + 1e-4 * rng.normal(size=(8, 8, 3)))
    h = rng.uniform(0, 1, (8, 8))
    for k in (0.5, 1e3):
        out.append((f"bump.bump_normals (n_z → 0, k_bump {k:g})",
                    lambda n, hh, kk=k: bump.bump_normals(n, hh, kk), [nmap, h]))
    # The general form (cylindrical, uv): ∇s along n (a tangent seen edge-on) on alternate
    # rows, n_z → 0, the seam's wrap, a huge k_bump.
    tilt = np.random.default_rng(1).normal(size=(8, 8, 3))
    g_s = np.where(np.arange(8)[:, None, None] % 2 == 0, nmap, [1.0, 0.0, 0.0]) + 1e-7 * tilt
    g_t = np.tile([0.0, 1.0, 0.0], (8, 8, 1))
    for k in (0.5, 1e3):
        out.append((f"bump.frame_bump_normals (∇s ∥ n, n_z → 0, seam, k_bump {k:g})",
                    lambda n, hh, a, b, kk=k: bump.frame_bump_normals(n, hh, kk, a, b, True),
                    [nmap, h, g_s, g_t]))
    # Texture sizes: a furrowed height field over a sphere-like normal map.
    for n in (64, 4096) if large else (64,):
        y, x = (np.mgrid[0:n, 0:n] + 0.5) / n * 2 - 1
        big = _unit(np.stack([x, y, np.sqrt(np.clip(1 - x * x - y * y, 0, None)) + 1e-7], -1))
        furrows = 1 - 0.25 * (np.sin(40 * np.pi * (x + 0.3 * y)) > 0.9)
        out.append((f"bump.bump_normals ({n}² texture, furrows, rim n_z → 0)",
                    lambda nn, hh: bump.bump_normals(nn, hh, 0.5), [big, furrows]))
    for d in (0.0, 2.0):  # the furrow field (not differentiable) at |d| = 0 and 2, bumped
        h_d = furrows_at(d)
        out.append((f"wrinkles |d| = {d:g}: noise + bump normals (k_noise, k_bump, h)",
                    lambda kn, kb, hh: bump.bump_normals(
                        jnp.broadcast_to(jnp.asarray([0.0, 0.0, 1.0], hh.dtype), (*hh.shape, 3)),
                        wrinkles.add_noise(hh, jnp.ones(hh.shape, bool), kn[0],
                                           jnp.full(hh.shape, 0.5, hh.dtype)), kb[0]),
                    [np.array([0.3]), np.array([0.5]), h_d]))
    out += cosmetics_cases(N, L, large)
    return out


def furrows_at(d: float, n: int = 64) -> np.ndarray:
    """The furrow height field of constant fields of magnitude `d` on an n² square."""
    mask = jnp.ones((n, n), bool)
    f1 = jnp.broadcast_to(jnp.asarray([d, 0.0], jnp.float32), (n, n, 2))
    f2 = jnp.broadcast_to(jnp.asarray([0.0, d], jnp.float32), (n, n, 2))
    seeds = jnp.asarray((np.mgrid[4:n:8, 4:n:8].reshape(2, -1).T + 0.5), jnp.float32)
    h, _ = wrinkles.height_field(mask, f1, f2, seeds, 1.0, jax.random.key(0),
                                 radius=wrinkles.window_radius(1.0))
    return np.asarray(h, np.float64)


def cosmetics_cases(N, L, large=False):
    """Issue 6's stages: the layered model per texel (thickness 0 to 10 mm, S → 0, K → 0,
    K/S 1e6, grazing light, n_z → 0), the skin blur (a point of light at a mesh edge, 64²
    to 2048²), melanin, the sRGB encoding at 0 and below, and a whole makeup render with
    empty cosmetic maps."""
    from jaxskin import cosmetics, formats, render, skin, spectral, sss
    from jaxskin.scene import load_scene
    from jaxskin.shading import layered

    grid = spectral.Grid(step=20)
    mats = [cosmetics.load_material(n, grid) for n in ("foundation_beige", "blush_rose",
                                                       "lipstick_red")]
    S0, K0 = np.stack([m.S for m in mats]), np.stack([m.K for m in mats])
    skin_R = formats.nist_reflectance(12, grid)
    thick = np.array([0.0, 1e-6, 0.01, 10.0])
    X = np.stack([np.repeat(thick, len(N) // len(thick) + 1)[:len(N)]] * 3)
    X[1] = X[1][::-1]
    out = []

    def shade(n, l_, x, S, K):
        # S and K are arguments, not constants, so that the four cases are one program;
        # their gradients are not asked for (∂R/∂K → −∞ as K → 0 under a thick layer)
        dt = n.dtype  # a light direction per texel, grazing ones included
        S, K = jax.lax.stop_gradient(S), jax.lax.stop_gradient(K)
        return layered.radiance(grid, n, l_, jnp.asarray([0.0, 0.0, 1.0], dt), 0.25, 0.9,
                                jnp.asarray(skin_R, dt), 0.3, 0.18, S, K, x,
                                jnp.asarray([0.45, 0.35, 0.2], dt),
                                jnp.asarray([0.05, 0.05, 0.3], dt))

    for label, s_scale, k_scale in [("ordinary", 1.0, 1.0), ("S → 0", 1e-9, 1.0),
                                    ("K → 0", 1.0, 1e-9), ("K/S 1e6", 1e-3, 1e3)]:
        out.append((f"layered.radiance ({label}; thickness 0–10 mm, grazing, n_z → 0)",
                    shade, [N, L, X, S0 * s_scale, K0 * k_scale]))
    for n in (64, 512, 2048) if large else (64, 512):
        E = np.zeros((n, n, 3))
        E[n // 2, n // 2] = 1.0  # a point of light
        E[:, : n // 4] = 0.7
        mask = np.ones((n, n), bool)
        mask[:, n // 8: n // 4] = False  # an edge of the mesh
        out.append((f"sss.blur (a point of light, a mesh edge, {n}²)",
                    lambda e, m=mask: sss.blur(e, 0.2, m), [E]))
    out.append(("skin.reflectance (melanin 0–3)",
                lambda m: skin.reflectance(jnp.asarray(skin_R, m.dtype), m[:, None], grid),
                [np.array([0.0, 1e-6, 1.0, 3.0])]))
    out.append(("render.encode_srgb (−1 to 2, 0 and 0.0031308)", render.encode_srgb,
                [np.array([-1.0, -1e-9, 0.0, 1e-9, 0.0031308, 0.5, 1.0, 2.0])]))

    scene = load_scene("makeup", ["texture.size=32", "camera.size=16"])
    arrays = render.prepare(scene.config).arrays

    def empty_maps(t):
        a = jax.tree.map(lambda v: v.astype(t.dtype) if jnp.issubdtype(v.dtype, jnp.floating)
                         else v, arrays)
        a = {**a, "cover": jnp.zeros_like(a["cover"])}
        p = {k: jnp.asarray(v, t.dtype) for k, v in scene.params.items()}
        return jax.vmap(lambda x: render.render_prepared(
            scene.config, {**p, "layer.foundation.thickness_mm": x}, a))(t)

    out.append(("makeup render (empty cosmetic maps, thickness 0–10 mm)", empty_maps,
                [thick]))
    return out


@functools.cache
def _value_and_grads(fn):
    """`fn`'s value and the gradient of its sum with respect to every argument, as one
    jitted program, as the renderer runs them (op by op, a stage took up to 25 s): the
    value is the one the gradient's forward pass computes (every custom rule in jaxskin
    recomputes its primal with the plain function), so it is not compiled twice. Cached
    per function: stages that share one (the layered cases) share its programs."""
    def value_and_grads(*a):
        value, pullback = jax.vjp(fn, *a)
        return value, pullback(jnp.ones_like(value))  # = jax.grad of jnp.sum(fn)

    return jax.jit(value_and_grads)


def run(stage, fn, inputs):
    """Non-finite counts and the float32 error for one stage."""
    row = {"stage": stage, "cases": int(np.prod(np.shape(inputs[0])[:1] or [1]))}
    results = {}
    for dtype in (jnp.float32, jnp.float64):
        with jax.enable_x64(dtype == jnp.float64):
            args = [jnp.asarray(a, dtype) for a in inputs]
            value, grads = _value_and_grads(fn)(*args)
            name = "f32" if dtype == jnp.float32 else "f64"
            row[f"nonfinite_{name}"] = int(np.sum(~np.isfinite(np.asarray(value))))
            row[f"nonfinite_grad_{name}"] = int(sum(np.sum(~np.isfinite(np.asarray(g)))
                                                    for g in grads))
            results[name] = np.asarray(value, np.float64)
    row["max_f32_error"] = float(np.max(np.abs(results["f32"] - results["f64"])))
    return row


def sweep():
    return [run(*c) for c in cases(large=True)]


def main():
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from common import machine, table, write_section

    rows = sweep()
    t = table(["stage", "non-finite values f32 / f64", "non-finite gradients f32 / f64",
               "max |f32 − f64|"],
              [(r["stage"], f"{r['nonfinite_f32']} / {r['nonfinite_f64']}",
                f"{r['nonfinite_grad_f32']} / {r['nonfinite_grad_f64']}",
                f"{r['max_f32_error']:.1e}") for r in rows])
    print(t)
    write_section("stability", f"""## Numerical stability (part of issue 8)

Command: `python benchmarks/stability.py`. Machine: {machine()}.

Every differentiable stage, on grids of stiff and extreme inputs, in float32 and float64,
jitted as the renderer runs it. Gradients are of the sum of the outputs with respect to every
input.
`tests/test_stability.py` runs the same sweep, less the 4096² and 2048² cases (10 GB),
and fails on any non-finite value or gradient, or a float32 error above 1e-5 (outputs are
reflectances, colours, unit vectors).

{t}
""")


if __name__ == "__main__":
    main()
