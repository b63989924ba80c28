"""Furrow height field benchmark: the jitted program against its NumPy transcription, and
the sequential program against the parallel (lockstep) one.

    python benchmarks/bench_wrinkles.py        # about 5 minutes on 2 cores
    python benchmarks/bench_wrinkles.py --parallel   # only sequential against parallel
    python benchmarks/bench_wrinkles.py --speed      # the two programs' times alone
    python benchmarks/bench_wrinkles.py --quick      # tiny sizes: checks that it runs

The built-in hand scene (Bando 2001 fig. 6.1: planar, k_scale 1.1) at 512² and 2048²
texels: cold (trace + compile + run) and warm times of `jaxskin.wrinkles.height_field`, and
the same algorithm in benchmarks/numpy_furrows.py (a Python loop over seeds and steps,
NumPy on each step's window), in the same run. The paper: 8–10 s at 512² (Athlon 1 GHz and
a GeForce, 2001). Writes the `wrinkles` section of RESULTS.md, then `wrinkles-parallel`
(`--parallel`: that one only); `--speed` writes `wrinkles-speed` (the GPU check's: both
programs at 512² and 2048² on whichever device JAX has, the parallel one best of
`--repeat`). `--results FILE` writes them there instead.
"""

from __future__ import annotations

import functools
import sys
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import common  # noqa: E402
import numpy_furrows  # noqa: E402
from common import machine, table, timeit, write_section  # noqa: E402

from jaxskin import furrow_stats, lockstep, texture, wrinkles  # noqa: E402
from jaxskin.scene import load_scene  # noqa: E402


def inputs(size):
    sc = load_scene("hand", [f"texture.size={size}"])
    s = texture.setup(sc.config.texture)
    cent = jnp.asarray(s.tmap.centroids(), jnp.float32)
    radius = wrinkles.window_radius(sc.config.texture.k_scale)
    return sc, s, cent, radius


QUICK = (64, 128)  # --quick's texture sizes


def main(argv: list[str] | None = None):
    def modes(ap):
        ap.add_argument("--parallel", action="store_true",
                        help="only the sequential program against the parallel one")
        ap.add_argument("--speed", action="store_true",
                        help="only both programs' times on JAX's device (the GPU check)")

    args = common.options(__doc__, argv, modes)
    cmd = common.command("benchmarks/bench_wrinkles.py", argv)
    if args.speed:
        speed(QUICK if args.quick else (512, 2048), args.repeat, cmd)
    elif args.parallel:
        parallel(QUICK if args.quick else (512, 1024, 1536, 2048), cmd)
    else:
        against_numpy(QUICK if args.quick else (512, 2048), cmd)
        parallel(QUICK if args.quick else (512, 1024, 1536, 2048), cmd)
    print(f"wrote {common.RESULTS}")


def against_numpy(sizes, cmd: str):
    print(machine())
    rows, counts = [], {}
    for size in sizes:
        sc, s, cent, radius = inputs(size)
        key = jax.random.key(sc.config.texture.seed)
        args = (s.mask, s.field1, s.field2, cent, sc.config.texture.k_scale, key)
        t0 = time.perf_counter()
        h, rec = wrinkles.height_field(*args, radius=radius)
        jax.block_until_ready(h)
        cold = time.perf_counter() - t0
        warm = timeit(lambda *a, r=radius: wrinkles.height_field(*a, radius=r)[0], *args,
                      repeat=3)
        counts[size] = [int(c) for c in rec.count]
        t0 = time.perf_counter()
        h_np = numpy_furrows.height_field(np.asarray(s.mask), np.asarray(s.field1),
                                          np.asarray(s.field2), np.asarray(cent),
                                          sc.config.texture.k_scale, key, radius,
                                          table_size=max(counts[size]) + 16)
        base = time.perf_counter() - t0
        same = float(np.mean(np.abs(np.asarray(h) - h_np) < 1e-4))
        rows.append((f"{size}²", f"{counts[size][0]} + {counts[size][1]}", f"{cold:.2f}",
                     f"{warm:.3f}", f"{base:.2f}", f"{base / warm:.0f}", f"{same:.4%}"))
        print(rows[-1], flush=True)
    t = table(["texture", "furrows F1 + F2", "cold s", "warm s", "NumPy s", "× NumPy",
               "texels equal to NumPy (1e-4)"], rows)
    print(t)
    body = f"""## Furrow height field (issue 4)

Command: `{cmd}`. Machine: {machine()}.

The built-in hand (Bando 2001 fig. 6.1, planar projection, k_scale 1.1, seed 0). Cold:
trace, compile and run; warm: best of repeated runs. The baseline is the same algorithm in
NumPy (`benchmarks/numpy_furrows.py`), drawing the same random turns; the last column is
the share of texels on which the two agree to 1e-4. Aim: 512² under 0.2 s warm, at least
30x the NumPy baseline. The paper: 8–10 s at 512².

{t}

The program is sequential by nature (each furrow depends on every earlier one through the
buffer B), so it runs on one core: one `lax.while_loop` over furrows, one over steps,
each step touching a (2R + 1)² window (R = {wrinkles.window_radius(1.1)} texels at k_scale
1.1). What it took, measured at 512² / 2048²: vmapping the two passes turned every window
update into a scatter over the whole image (2.08 s at 512²); running them one after the
other gave 0.13 s / 14 s; a read of the image that did not feed its in-place update (a
per-row count of free texels for the seed search) made XLA copy the whole image at every
step, and removing it (the seed search scans rows from a cursor inside the step loop) gave
the times above.
"""
    write_section("wrinkles", body)


def side_by_side(size, repeat=3):
    """Warm times of both programs on the hand at `size`² (interleaved, best of `repeat`
    each, so both see the same load), their cold times, and the character figures."""
    sc, s, cent, radius = inputs(size)
    k, key = sc.config.texture.k_scale, jax.random.key(sc.config.texture.seed)
    records = 65536
    args = (s.mask, s.field1, s.field2)  # arguments, not constants folded into the program
    seq = functools.partial(wrinkles.height_field, *args, cent, k, key, radius=radius,
                            records=records)
    par = functools.partial(lockstep.height_field, *args, k, key, records=records)
    cold, warm, out = {}, {"seq": [], "par": []}, {}
    for name, fn in (("seq", seq), ("par", par)):
        t0 = time.perf_counter()
        out[name] = jax.block_until_ready(fn())
        cold[name] = time.perf_counter() - t0
    for _ in range(repeat):
        for name, fn in (("seq", seq), ("par", par)):
            t0 = time.perf_counter()
            jax.block_until_ready(fn())
            warm[name].append(time.perf_counter() - t0)
    stats = furrow_stats.compare(np.asarray(s.mask), np.asarray(out["seq"][0]),
                                 wrinkles.to_numpy_record(out["seq"][1], records),
                                 np.asarray(out["par"][0]),
                                 wrinkles.to_numpy_record(out["par"][1], records))
    counts = {n: [int(c) for c in out[n][1].count] for n in out}
    return cold, {n: min(t) for n, t in warm.items()}, stats, counts


def parallel(sizes, cmd: str):
    rows, char = [], []
    for size in sizes:
        cold, warm, st, counts = side_by_side(size)
        rows.append((f"{size}²", lockstep.slots_for(size, size),
                     f"{cold['seq']:.1f} / {cold['par']:.1f}",
                     f"{warm['seq']:.3f}", f"{warm['par']:.3f}",
                     f"{warm['seq'] / warm['par']:.2f}"))
        cov = st["coverage"]
        for p in range(2):
            tj, ln = st["t_junctions"][p], st["lengths"][p]
            char.append((f"{size}²", f"F{p + 1}", f"{counts['seq'][p]} / {counts['par'][p]}",
                         f"{cov[0]:.3f} / {cov[1]:.3f}" if p == 0 else "",
                         f"{st['orientation'][p]:.3f}", f"{tj[0]:.2f} / {tj[1]:.2f}",
                         f"{ln[0]:.0f} / {ln[1]:.0f}", f"{ln[2]:.0f} / {ln[3]:.0f}",
                         f"{ln[4]:.3f}"))
        print(rows[-1], char[-2:], flush=True)
    t = table(["texture", "slots", "cold s seq / par", "warm s sequential", "warm s parallel",
               "sequential / parallel"], rows)
    c = table(["texture", "pass", "furrows seq / par", "coverage seq / par",
               "orientation histogram distance", "ends at a furrow (T) seq / par",
               "median length seq / par", "90th pct length", "KS distance of lengths"], char)
    body = f"""## Parallel furrow program (issue 19)

Command: `{cmd}` (this section: `parallel()`). Machine:
{machine()}. Pictures: `python benchmarks/furrow_pictures.py` →
`benchmarks/furrows_side_by_side.png`.

The sequential program (`wrinkles.height_field`) against the lockstep one
(`lockstep.height_field`, `wrinkles.method = "parallel"`) on the hand (k_scale 1.1), in one
run: cold (trace + compile + run), then warm runs interleaved (best of 3 each, so both see
the same load on a shared machine).

{t}

Their character, the same runs (`jaxskin.furrow_stats.compare`): coverage is the share of
mesh texels a furrow lowered; the orientation histogram distance is the total variation
distance (0–1) of the two programs' structure-tensor orientation histograms (18 bins) of
each pass's furrows; "ends at a furrow" is the share of furrow halves that stopped on
another furrow of their pass (T-junctions); lengths are whole furrows in texels, with the
two-sample Kolmogorov–Smirnov distance of their distributions. The pictures (rows: hand,
arm, face; columns: sequential and parallel at 512², then the middle 512² of each at 2048²):

![sequential against parallel furrows](furrows_side_by_side.png)

{c}

How it is built (`jaxskin/lockstep.py`): `slots` furrows (one per 4096 texels) each take a
step per iteration of one `lax.while_loop` per pass; a slot whose furrow ended takes the
next seed of a queue (seeds in four rounds, one jittered point per cell of grids of
48, 12, 6 and 3 texels at k_scale 1.1, in a scrambled order, each taken only if B is free
around it); each step draws its segment with one flat scatter-min into the image and one
into the owner image, over a band-shaped window along the segment (91 texels at k_scale
1.1; the sequential program's square window is 729). What it took, measured with the
profiler at 2048²: `jnp.hypot` in the window made the step 3x slower than `sqrt`; threefry
per step (the random turn) cost as much as the rest of the step, replaced by an integer
hash; a sort per round, by a fixed scrambled order; waiting for every furrow of a round
before the next (tails of up to 64 steps), by making the next round's queue as soon as the
last one is used up (the seeds' positions are also materialised before the B test, which
XLA had fused into every ring point's read). More slots cut long furrows short (at one
per 2048 texels the 90th percentile of lengths on the 512² hand fell from 132 to 94
texels), so the slot count is a trade of speed for likeness.

**GPU** (one H200, 2026-12-04, `bench_wrinkles.py --speed`; the issue 19 section has the
table): 8.4 ms at 512² and 12.2 ms at 2048², against the sequential program's 0.72 s and
8.94 s on the same GPU (86× and 731×; the aims: under 20 ms at 512², at least 50× at
2048²), with the furrow counts of the CPU runs. It is launch-bound, as estimated before
that run (15–35 ms and 20–40 ms): about 75 iterations per pass at 512² (64 slots) and 83 at
2048² (1024 slots), each some 20 fused kernels over (slots × 91) elements. The
scene's `wrinkles.method = "auto"` picks this program on a GPU or TPU, and on a CPU from
2048² (`scene.PARALLEL_FROM_SIZE_ON_CPU`): there the two are about as quick from a cold
start (the first table's cold column: trace, compile, first run, what a one-off render
pays; at 4096², 10.4 s sequential against 8.1 s parallel, measured separately), below it
the sequential program compiles about a second sooner, more than the parallel one saves in
running. Every built-in scene is 512², so their default look on a CPU (and their golden
images, which name the method) is the sequential program's; on a GPU, the parallel one's.
"""
    write_section("wrinkles-parallel", body)


def speed(sizes, repeat: int, cmd: str):
    """Times alone, on whichever device JAX has (the GPU check): both programs at each size,
    cold then warm (parallel: best of `repeat`; sequential: one warm run, seconds a run on a
    GPU), with the furrow counts per pass (the same inputs give the same counts on any
    device, up to float rounding in the seeds' tests). No NumPy baseline, no statistics."""
    from common import device

    rows = []
    for size in sizes:
        sc, s, cent, radius = inputs(size)
        k, key = sc.config.texture.k_scale, jax.random.key(sc.config.texture.seed)
        args = (s.mask, s.field1, s.field2)
        par = functools.partial(lockstep.height_field, *args, k, key)
        seq = functools.partial(wrinkles.height_field, *args, cent, k, key, radius=radius)
        out, cold, warm = {}, {}, {}
        for name, fn, n in (("par", par, repeat), ("seq", seq, 1)):
            t0 = time.perf_counter()
            out[name] = jax.block_until_ready(fn())
            cold[name] = time.perf_counter() - t0
            warm[name] = timeit(lambda f=fn: f()[0], repeat=n, warmup=0)
        counts = {n: "+".join(str(int(c)) for c in out[n][1].count) for n in out}
        rows.append((f"{size}²", lockstep.slots_for(size, size),
                     f"{cold['seq']:.2f} / {cold['par']:.2f}", f"{warm['seq'] * 1e3:.1f}",
                     f"{warm['par'] * 1e3:.1f}", f"{warm['seq'] / warm['par']:.1f}",
                     f"{counts['seq']} / {counts['par']}"))
        print(rows[-1], flush=True)
    t = table(["texture", "slots", "cold s seq / par", "warm ms sequential",
               "warm ms parallel", "sequential / parallel", "furrows F1+F2 seq / par"], rows)
    print(t)
    write_section("wrinkles-speed", f"""## Furrow programs' speed on the device (issue 19)

Command: `{cmd}`. Machine: {machine()}. Device: {device()}.

The hand (k_scale 1.1): cold (trace + compile + run), then warm, the parallel program
best of {repeat}, the sequential one a single warm run.

{t}
""")


if __name__ == "__main__":
    main(sys.argv[1:])
