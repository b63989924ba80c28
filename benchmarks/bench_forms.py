"""The makeup derivative's XLA forms, one variant a process (issue 19): the makeup face at
1280×720, forward, gradient with respect to the 21 scalars and to the thickness maps, warm,
timed in turn, best of 8 rounds.

    python benchmarks/bench_forms.py plain     # the forms a GPU gets (`layered._cpu_form`)
    python benchmarks/bench_forms.py cpu       # XLA:CPU's forms (chunks aside: one wide one)
    python benchmarks/bench_forms.py plain+apart   # plain, but one named CPU form
    python benchmarks/bench_forms.py plain --quick # tiny sizes: checks that it runs

A variant is `cpu`, `plain`, or `plain+NAME` with NAME one of `apart`, `skip`, `sums`
(`layered._cpu_form` says what each is). Chunking is one wide chunk in every variant (on a
CPU as well: compare variants on the device they are meant for). Run each variant in its
own process: the forms are read when the derivative is traced, and jit keeps the first
trace. Prints one line.
"""

from __future__ import annotations

import sys
import time

import jax
import jax.numpy as jnp

from jaxskin import render
from jaxskin.scene import load_scene
from jaxskin.shading import layered

FORMS = {"cpu": {"apart", "skip", "sums"}, "plain": set(), "plain+apart": {"apart"},
         "plain+skip": {"skip"}, "plain+sums": {"sums"}}


def main(argv: list[str]) -> int:
    import argparse

    ap = argparse.ArgumentParser(description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("variant", choices=list(FORMS), help="which forms to trace")
    ap.add_argument("--quick", action="store_true", help="tiny sizes (a check that it runs)")
    args = ap.parse_args(argv)
    variant, forms = args.variant, FORMS[args.variant]
    layered._cpu_form = lambda name: name in forms  # "chunks" never: one wide chunk
    sc = load_scene("makeup", ["texture.size=64", "camera.size=32"] if args.quick
                    else ["camera.size=1280", "camera.height=720"])
    config, params = sc.config, sc.params
    arrays = render.prepare(config).arrays
    keys = [k for k in params if k.startswith("layer.")] + ["skin.melanin"]

    def image_sum(p, a):
        return jnp.sum(render.render_prepared(config, p, a))

    calls = {
        "forward": (jax.jit(lambda p, a: render.render_prepared(config, p, a)),
                    (params, arrays)),
        "scalars": (jax.jit(jax.grad(lambda sub, a: image_sum({**params, **sub}, a))),
                    ({k: params[k] for k in keys}, arrays)),
        "maps": (jax.jit(jax.grad(lambda cover, a: image_sum(params, {**a, "cover": cover}))),
                 (arrays["cover"], arrays)),
    }
    for fn, args in calls.values():  # warm: compiled and run once
        jax.block_until_ready(fn(*args))
    best = dict.fromkeys(calls, float("inf"))
    for _ in range(8):
        for name, (fn, args) in calls.items():
            t0 = time.perf_counter()
            jax.block_until_ready(fn(*args))
            best[name] = min(best[name], time.perf_counter() - t0)
    f = best["forward"]
    print(f"{variant:12s} forward {f * 1e3:.2f} ms  scalars {best['scalars'] * 1e3:.2f} ms "
          f"{best['scalars'] / f:.2f}x  maps {best['maps'] * 1e3:.2f} ms "
          f"{best['maps'] / f:.2f}x  ({jax.devices()[0].device_kind})", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
