"""How far each hot stage is from this machine's limits (issue 8).

    python benchmarks/limits.py              # about a minute on 2 cores
    python benchmarks/limits.py --quick      # tiny sizes: checks that it runs

Two limits, both measured here rather than taken from a data sheet:

- memory: the time of the stage's own input and output bytes passing through memory once
  (a fused, jitted `x * 1.0001` over an array of half those bytes: it reads them and writes
  as many), so "× memory" is how many such passes the stage costs; measured as one call
  writing a fresh output, as a stage does, and in place, many passes in one program (the
  memory's own rate: no first touch of a fresh output, no dispatch);
- arithmetic: XLA's own count of the stage's floating-point operations (`cost_analysis()`
  of the compiled program; a transcendental counts as one) against this machine's peak,
  measured as a 2048² float32 matmul at `Precision.HIGHEST` (the renderer's precision), so
  "× peak" is the stage's time over that ideal.

A stage far above both lines is bound by neither: by how XLA schedules it (fusion,
materialised intermediates) or by latency. The furrow program (issue 19) gets the memory
line only: the texels it must touch once (its direction fields, mask and centroids read,
its height field written); XLA counts a loop body once, not per trip, so its arithmetic
count means nothing. The gradients with respect to the makeup's thickness maps and the
Blinn material are stages too (their inputs and the gradient's bytes). Everything runs on
JAX's default device, and the memory pass and the peak are measured on that device.
Writes the `limits` section of RESULTS.md (or of the file `--results` names).
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
from common import device, machine, table, timeit, write_section  # noqa: E402

from jaxskin import render, spectral, sss, wrinkles  # noqa: E402
from jaxskin.scene import load_scene  # noqa: E402

PASSES = 20  # in-place memory passes in one program (`memory_pass`)


def peak_flops() -> float:
    """A 2048² float32 matmul's rate at `Precision.HIGHEST`, the renderer's precision (at
    the default a GPU multiplies in TF32: 83.6 TFLOP/s on an H200, above float32's peak)."""
    n = 2048
    a = jnp.asarray(np.random.default_rng(0).uniform(size=(n, n)), jnp.float32)
    t = timeit(jax.jit(lambda x: jnp.matmul(x, x, precision=jax.lax.Precision.HIGHEST)), a,
               repeat=5)
    return 2 * n**3 / t


def memory_pass(nbytes: int) -> tuple[float, float]:
    """Seconds of one pass of `nbytes` (read `nbytes / 2`, write as many, fused), two ways:
    one call writing a fresh output, as a stage does (on a CPU the output's first touch, on
    a GPU the call's dispatch and launch, are part of it: 18 of 20 ms for 185 MB on the
    2-core CPU; an H200's 64 MB pass took 0.19 ms, 0.34 TB/s), and in place, `PASSES` in one
    program, the time of one (the memory's own rate)."""
    x = jnp.ones(max(int(nbytes) // 8, 1), jnp.float32)
    call = timeit(jax.jit(lambda v: v * 1.0001), x, repeat=5)
    passes = jax.jit(lambda v: jax.lax.fori_loop(0, PASSES, lambda _, w: w * 1.0001, v))
    return call, timeit(passes, x, repeat=5) / PASSES


def stages(quick: bool = False):
    """(name, jitted function, arguments, loop) of the hot stages, at their benchmark
    sizes (`quick`: tiny ones); `loop`: a program of loops, whose arithmetic XLA does not
    count per trip."""
    out = []
    import bench_km

    tex, km_size, sss_size = (64, 32, 32) if quick else (1024, 1024, 512)
    grid = spectral.Grid(10)
    wl = grid.wavelengths
    S, K = bench_km.load_materials(wl)
    X = bench_km.thickness_maps(km_size)
    Rg = bench_km.skin_reflectance(wl)
    args = [jnp.asarray(a, jnp.float32) for a in (S, K, X, Rg)]
    out.append((f"KM: 3 layers over skin, {km_size}² × 41 bands",
                jax.jit(bench_km.over_skin), args, False))
    hand = [f"texture.size={tex}", f"camera.size={tex // 2}"]
    face = [f"texture.size={tex // 2}"] + (["camera.size=32"] if quick else
                                            ["camera.size=1280", "camera.height=720"])
    hand_label = f"hand, {tex // 2}² from {tex}²"
    face_label = "makeup face, " + ("quick" if quick else "1280×720")
    for label, name, overrides, grad in [
            (f"render: {hand_label}, Blinn", "hand", hand, None),
            (f"render: {hand_label}, Lafortune", "hand",
             hand + ["material.model=lafortune"], None),
            (f"render: {face_label} (4 layers, SSS)", "makeup", face, None),
            (f"render: {face_label}, SSS off", "makeup", face + ["sss.enabled=false"], None),
            (f"gradient: {hand_label}, Blinn, d(mean image)/d(material)", "hand", hand,
             "material"),
            (f"gradient: {face_label}, d(sum image)/d(thickness maps)", "makeup", face,
             "maps")]:
        sc = load_scene(name, overrides)
        arrays = render.prepare(sc.config).arrays
        if grad is None:
            f = jax.jit(lambda p, a, c=sc.config: render.render_prepared(c, p, a))
            out.append((label, f, [sc.params, arrays], False))
        elif grad == "maps":
            f = jax.jit(jax.grad(lambda cover, a, c=sc.config, p=sc.params: jnp.sum(
                render.render_prepared(c, p, {**a, "cover": cover}))))
            out.append((label, f, [arrays["cover"], arrays], False))
        else:
            keys = [k for k in sc.params if k.startswith("material.")]
            f = jax.jit(jax.grad(lambda sub, a, c=sc.config, p=sc.params: jnp.mean(
                render.render_prepared(c, {**p, **sub}, a))))
            out.append((label, f, [{k: sc.params[k] for k in keys}, arrays], False))
    E = jnp.asarray(np.random.default_rng(1).uniform(size=(sss_size, sss_size, 3)),
                    jnp.float32)
    out.append((f"SSS blur by FFT, {sss_size}², 0.2 mm texels",
                jax.jit(lambda e: sss.blur(e, 0.2)), [E], False))
    out += furrow_stages(32 if quick else 512)
    return out


def furrow_stages(size: int):
    """The furrow programs on the hand at `size`², sequential and parallel (lockstep): the
    texels they touch once are their inputs (mask, two direction fields, centroids) and
    their height field."""
    import bench_wrinkles

    from jaxskin import lockstep

    sc, s, cent, radius = bench_wrinkles.inputs(size)
    k, key = sc.config.texture.k_scale, jax.random.key(sc.config.texture.seed)

    def sequential(mask, f1, f2, cent, key):
        return wrinkles.height_field(mask, f1, f2, cent, k, key, radius=radius)[0]

    def parallel(mask, f1, f2, key):
        return lockstep.height_field(mask, f1, f2, k, key)[0]

    return [(f"furrows, sequential: hand {size}² (program of loops)", sequential,
             [s.mask, s.field1, s.field2, cent, key], True),
            (f"furrows, parallel: hand {size}² (program of loops)", parallel,
             [s.mask, s.field1, s.field2, key], True)]


_CPU_READING = """\
Reading (of the 2-core CPU runs; a GPU's is in the issue 19 section): the KM texture is
the stage nearest its limits, 7–8× a memory pass of its 185 MB and 7–8× its arithmetic at
peak (over this session's runs); what is left is XLA's materialised intermediates. The
renders sit far above both lines (tens of × a pass of their bytes, which fit in this CPU's
cache, so the pass itself is fast; 10–90× peak): small per-pixel work, gathers (bilinear
view sampling, texel lists) that XLA does not count as arithmetic, and for the makeup face
the three spectral colours computed apart (`layered._separately`). The FFT blur is 3× its
arithmetic ideal. The gaps are where a custom kernel could gain; no XLA flag closes them.
(That reading is issue 8's, from a run without the gradient and furrow rows; those are
issue 19's: the furrow row's memory line is the time to touch its texels once, the floor a
parallel furrow program could reach.)"""


def _nbytes(tree) -> int:
    """Bytes of the arrays in `tree` (random keys and Python scalars: none)."""
    return int(sum(a.nbytes for a in jax.tree.leaves(tree) if hasattr(a, "nbytes")
                   and not jax.dtypes.issubdtype(a.dtype, jax.dtypes.prng_key)))


def main(argv: list[str] | None = None):
    opts = common.options(__doc__, argv)
    print(machine())
    peak = peak_flops()
    rows = []
    for name, f, args, loop in stages(opts.quick):
        t = timeit(f, *args, repeat=opts.repeat)
        out = f(*args)
        nbytes = _nbytes(args) + _nbytes(out)
        t_mem, t_stream = memory_pass(nbytes)
        if loop:
            flops_cols = ("—", "—", "—")
        else:
            cost = f.lower(*args).compile().cost_analysis()
            cost = cost[0] if isinstance(cost, list) else cost
            flops = float(cost.get("flops", 0.0)) + float(cost.get("transcendentals", 0.0))
            t_peak = flops / peak
            flops_cols = (f"{flops / 1e9:.3g}", f"{t_peak * 1e3:.3g}", f"{t / t_peak:.0f}×")
        rows.append((name, f"{t * 1e3:.2f}", f"{nbytes / 1e6:.1f}", f"{t_mem * 1e3:.3f}",
                     f"{t / t_mem:.1f}×", f"{t_stream * 1e3:.3f}", f"{t / t_stream:.0f}×",
                     *flops_cols))
        print(rows[-1], flush=True)
    t = table(["stage", "warm ms", "in + out MB", "memory pass ms", "× memory",
               "in-place pass ms", "× in place",
               "XLA GFLOP", "at peak ms", "× peak"], rows)
    print(f"peak {peak / 1e9:.0f} GFLOP/s (float32 matmul)")
    print(t)
    command = common.command("benchmarks/limits.py", argv)
    reading = _CPU_READING if jax.default_backend() == "cpu" and not opts.quick else (
        "No reading is written for this run (tiny sizes, or not a CPU): read the table. The "
        "2-core CPU's reading is in RESULTS.md's `limits` section, an H200's in its issue 19 "
        "section.")
    write_section("limits", f"""## Physical limits: memory and arithmetic (issues 8, 19)

Command: `{command}`. Machine: {machine()}. Device: {device()}.

Peak arithmetic measured as a 2048² float32 matmul at `Precision.HIGHEST`: {peak / 1e9:.0f}
GFLOP/s. "memory pass": the stage's input and output bytes read and written once by a
fused copy, one call writing a fresh output as a stage does; "in-place pass": the same
copy in place, {PASSES} in one program, the time of one (the memory's own rate, without the
fresh output's first touch or the call's dispatch); "XLA GFLOP": XLA's count for the
compiled program (transcendentals as one each). Warm times: the best of {opts.repeat}
calls. "—": a program of loops, whose arithmetic XLA counts once per loop body, not per
trip (no arithmetic line).

{t}

{reading}
""")


if __name__ == "__main__":
    main(sys.argv[1:])
