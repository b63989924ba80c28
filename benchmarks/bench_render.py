"""Render benchmark: the hand, a 512² image from a 1024² texture, Blinn and Lafortune.

    python benchmarks/bench_render.py        # about a minute on 2 cores

Cold: the first `render` of a configuration in this process, including tracing, compiling
and the host-side preparation (mesh, projection, raster, furrows, view). Warm: later calls.
Also the gradient of an image loss with respect to the material, and a sweep of 16
melanin values vmapped against 16 separate calls. The paper: 10.5–19 fps (a 2001 GPU).
Writes the `render` section of RESULTS.md.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import HERE, machine, table, timeit, write_section  # noqa: E402

from jaxskin import render  # noqa: E402
from jaxskin.scene import load_scene  # noqa: E402

OVERRIDES = ["texture.size=1024", "camera.size=512"]


def main():
    print(machine())
    rows = []
    results = {}
    for model in ("blinn", "lafortune"):
        sc = load_scene("hand", [*OVERRIDES, f"material.model={model}"])
        config, params = sc.config, sc.params
        t0 = time.perf_counter()
        jax.block_until_ready(render.render(config, params))
        cold = time.perf_counter() - t0
        warm = timeit(render.render, config, params, repeat=10)
        keys = (["material.melanin", "material.blood", "material.specular",
                 "material.shininess"] if model == "blinn" else ["material.lafortune"])

        def loss(sub, arrays, config=config, params=params):
            image = render.render_prepared(config, {**params, **sub}, arrays)
            return jnp.mean((image - 0.5) ** 2)

        # The prepared arrays are arguments, as in `render`: closed over, XLA would fold
        # the texture-space work into constants and the comparison would be meaningless.
        grad = jax.jit(jax.grad(loss))
        sub = {k: params[k] for k in keys}
        g_warm = timeit(grad, sub, render.prepare(config).arrays, repeat=5)
        results[model] = warm
        rows.append((model, f"{cold:.2f}", f"{warm * 1e3:.1f}", f"{1 / warm:.0f}",
                     f"{g_warm * 1e3:.1f}", f"{g_warm / warm:.2f}"))
        print(rows[-1], flush=True)
    t1 = table(["material", "cold s", "warm ms", "fps", "gradient ms", "gradient / forward"],
               rows)

    sc = load_scene("hand", OVERRIDES)
    config, params = sc.config, sc.params
    values = jnp.linspace(0.0, 1.0, 16)
    arrays = render.prepare(config).arrays
    batch = jax.jit(jax.vmap(lambda v, a: render.render_prepared(
        config, {**params, "material.melanin": v}, a), in_axes=(0, None)))
    t_vmap = timeit(batch, values, arrays, repeat=3)

    def separate(values):
        return [render.render(config, {**params, "material.melanin": v}) for v in values]

    t_loop = timeit(separate, values, repeat=3)
    t2 = table(["16 melanin values", "warm ms", "per image ms", "× vmapped"],
               [("vmapped, one program", f"{t_vmap * 1e3:.0f}", f"{t_vmap / 16 * 1e3:.1f}",
                 "1.00"),
                ("16 separate calls", f"{t_loop * 1e3:.0f}", f"{t_loop / 16 * 1e3:.1f}",
                 f"{t_loop / t_vmap:.2f}")])
    print(t1)
    print(t2)
    body = f"""## Render (issue 5)

Command: `python benchmarks/bench_render.py`. Machine: {machine()}.

The built-in hand (Table 6.2's parameters), a 1024² texture, a 512² orthographic image.
Cold: the first render of the configuration in the process (host preparation — mesh,
projection, rasterization, fields, furrows, view — plus trace and compile). Warm: best of
10. The gradient is of an image MSE with respect to the material parameters (Blinn:
melanin, blood, specular, shininess; Lafortune: all lobes). Aim: ≥ 25 fps warm for Blinn,
gradient ≤ 3x the forward time. The paper: 10.5–19 fps on a 2001 GPU.

{t1}

{t2}

In both the gradient and the sweep the prepared arrays (normal map, furrows, view) are
arguments of the jitted function, as in `render`; closed over, XLA folds them into
constants and the times mean nothing (we first measured a "gradient" 0.09x the forward
time that way). The vmapped sweep is faster per image because everything that does not
depend on melanin — bump, sampling, the highlight — is computed once for the batch.
"""
    write_section("render", body)
    print(f"wrote {HERE / 'RESULTS.md'}")


if __name__ == "__main__":
    main()
