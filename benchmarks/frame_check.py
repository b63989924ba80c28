"""Warm frame times of the built-in scenes at their defaults and with the new stages off.

    .venv/bin/python benchmarks/frame_check.py
    .venv/bin/python benchmarks/frame_check.py camera.size=64 texture.size=64   # appended

A quick check (about a minute) added after issue 14 made supersample 2 the default and
added shadows, face furrows and a fourth cosmetic layer; bench_render and bench_makeup
hold the full studies. Best and median of 5 warm calls, arrays passed as arguments.
"""

import sys
import time

import jax
import numpy as np

from jaxskin import render
from jaxskin.scene import load_scene


def t(name: str, overrides: list[str]) -> None:
    """Print the best and median warm frame of scene `name` with `overrides`."""
    sc = load_scene(name, overrides)
    a = render.prepare(sc.config).arrays
    f = jax.jit(lambda p, a: render.render_prepared(sc.config, p, a))
    jax.block_until_ready(f(sc.params, a))
    ts = []
    for _ in range(5):
        t0 = time.perf_counter()
        jax.block_until_ready(f(sc.params, a))
        ts.append(time.perf_counter() - t0)
    print(f"{name} {overrides}: best {min(ts) * 1e3:.2f} ms, "
          f"median {np.median(ts) * 1e3:.2f} ms", flush=True)


def main(extra: list[str]) -> int:
    """`extra`: overrides appended to every scene's (e.g. tiny sizes for a smoke run)."""
    print(f"device: {jax.devices()[0].platform}: {jax.devices()[0].device_kind}", flush=True)
    base = ["camera.size=1280", "camera.height=720"]
    t("makeup", base + extra)
    t("makeup", base + ["camera.supersample=1"] + extra)
    t("makeup", base + ["camera.supersample=1", "light.shadows=false",
                        "wrinkles.enabled=false"] + extra)
    t("hand", extra)
    t("hand", ["camera.supersample=1"] + extra)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
