"""Gradient against forward, every render model side by side (issue 19, item 2).

    python benchmarks/bench_gradients.py            # about a minute on 2 cores
    python benchmarks/bench_gradients.py --quick    # tiny sizes: checks that it runs
    python benchmarks/bench_gradients.py --chunking cpu   # a GPU with the CPU's chunks

In one process, warm (each function called once before timing), every call blocked on
(`jax.block_until_ready`); each row's forward and gradient timed in turn (forward,
gradient, forward; `repeat // 2` rounds), so that a change of load moves both alike, the
best of each (a scene's forward: the best over its rows so far):

- Blinn and Lafortune: the hand, a 512² image from a 1024² texture; the gradient of an
  image MSE with respect to the material's parameters (Blinn: melanin, blood, specular,
  shininess; Lafortune: every lobe);
- the cosmetics model (`makeup` scene, 1280×720, SSS): the gradient of the image's sum
  with respect to every scalar of the layers and the skin (thickness, S and K scales,
  roughness, specular, melanin), and with respect to the per-texel thickness maps, the
  `(layers, texels)` array the render consumes (`prepare(config).arrays["cover"]`, passed
  in as an argument the way an inverse render would pass its own maps).

Writes the `gradients` section of RESULTS.md (or of the file `--results` names).
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
from common import device, machine, table, timeit, write_section  # noqa: E402

from jaxskin import render  # noqa: E402
from jaxskin.scene import load_scene  # noqa: E402
from jaxskin.shading import layered  # noqa: E402

HAND = ["texture.size=1024", "camera.size=512"]
FACE = ["camera.size=1280", "camera.height=720"]
QUICK = {"hand": ["texture.size=64", "camera.size=32"],
         "makeup": ["texture.size=64", "camera.size=32"]}


def cases(quick: bool = False):
    """`(label, what, scene, overrides, loss maker)` of every measured gradient. A loss
    maker takes `(config, params, arrays)` and returns `(loss, argument)`: the loss of that
    argument (arrays passed along) and the argument's value."""
    def mse_of(keys):
        def make(config, params, arrays):
            def loss(sub, a):
                image = render.render_prepared(config, {**params, **sub}, a)
                return jnp.mean((image - 0.5) ** 2)
            return loss, {k: params[k] for k in keys}
        return make

    def sum_of_scalars(config, params, arrays):
        keys = [k for k in params if k.startswith("layer.")] + ["skin.melanin"]

        def loss(sub, a):
            return jnp.sum(render.render_prepared(config, {**params, **sub}, a))
        return loss, {k: params[k] for k in keys}

    def sum_of_maps(config, params, arrays):
        def loss(cover, a):
            return jnp.sum(render.render_prepared(config, params, {**a, "cover": cover}))
        return loss, arrays["cover"]

    hand = QUICK["hand"] if quick else HAND
    face = QUICK["makeup"] if quick else FACE
    blinn = ["material.melanin", "material.blood", "material.specular", "material.shininess"]
    sizes = {"hand": "hand, quick sizes" if quick else "hand 512² (1024² texture)",
             "makeup": "makeup, quick sizes" if quick else "makeup 1280×720 (512² texture)"}
    return [
        (f"Blinn, {sizes['hand']}", "4 material scalars", "hand", hand, mse_of(blinn)),
        (f"Lafortune, {sizes['hand']}", "every lobe", "hand",
         hand + ["material.model=lafortune"], mse_of(["material.lafortune"])),
        (f"spectral, {sizes['makeup']}", "every layer scalar + melanin", "makeup", face,
         sum_of_scalars),
        (f"spectral, {sizes['makeup']}", "per-texel thickness maps", "makeup", face,
         sum_of_maps),
    ]


def interleaved(f, f_args, g, g_args, repeat: int) -> tuple[float, float]:
    """Best wall times `(f, g)` in seconds, warm, timed in turn (f, g, f per round, `repeat`
    rounds), so that a change of the machine's load during the run moves both alike."""
    jax.block_until_ready(f(*f_args))
    jax.block_until_ready(g(*g_args))
    best_f = best_g = float("inf")
    for _ in range(repeat):
        best_f = min(best_f, timeit(f, *f_args, repeat=1, warmup=0))
        best_g = min(best_g, timeit(g, *g_args, repeat=1, warmup=0))
        best_f = min(best_f, timeit(f, *f_args, repeat=1, warmup=0))
    return best_f, best_g


def _ms(seconds: float) -> str:
    """Milliseconds to three significant figures (a GPU's 0.35 ms, a CPU's 151.4 ms)."""
    ms = seconds * 1e3
    return f"{ms:.1f}" if ms >= 100 else f"{ms:.3g}"


def measure(quick: bool = False, repeat: int = 5):
    """Rows `(model, with respect to, forward ms, gradient ms, ratio, gradient entries)`."""
    rows, forward = [], {}
    for label, what, name, overrides, make in cases(quick):
        sc = load_scene(name, overrides)
        config, params = sc.config, sc.params
        arrays = render.prepare(config).arrays
        key = (name, tuple(overrides))
        f = jax.jit(lambda p, a, c=config: render.render_prepared(c, p, a))
        loss, arg = make(config, params, arrays)
        g = jax.jit(jax.grad(loss))
        tf, tg = interleaved(f, (params, arrays), g, (arg, arrays), max(repeat // 2, 1))
        forward[key] = tf = min(tf, forward.get(key, tf))
        size = sum(x.size for x in jax.tree.leaves(arg))
        rows.append((label, what, _ms(tf), _ms(tg), f"{tg / tf:.2f}×",
                     f"{size:,}"))
        print(rows[-1], flush=True)
    return rows


def _chunking_option(ap):
    ap.add_argument("--chunking", choices=["device", "cpu"], default="device",
                    help="the makeup derivative's transpose loop: the device's own chunking "
                         "(default) or the CPU's (chunks of 1000 texels, two a step) on any "
                         "device; forward mode keeps its own chunks")


def main(argv: list[str] | None = None):
    args = common.options(__doc__, argv, _chunking_option)
    if args.chunking == "cpu":  # before anything is traced: jit keeps the first trace
        layered._chunking = lambda P: (layered.CHUNK, layered.STREAMS)
    print(machine())
    rows = measure(args.quick, args.repeat)
    t = table(["model", "gradient with respect to", "forward ms", "gradient ms",
               "gradient / forward", "entries"], rows)
    print(t)
    command = common.command("benchmarks/bench_gradients.py", argv)
    write_section("gradients", f"""## Gradients against the forward pass (issue 19)

Command: `{command}`. Machine: {machine()}. Device: {device()}.

Measured side by side in one process, warm, every call blocked on; per row the forward
and the gradient timed in turn (forward, gradient, forward; {max(args.repeat // 2, 1)}
rounds), the best of each (a scene's forward: the best over its rows so far). Blinn and Lafortune:
an image MSE; the makeup face: the image's sum. The thickness maps are the `(layers,
texels)` array the render consumes, passed in as an argument.

{t}
""")


if __name__ == "__main__":
    main(sys.argv[1:])
