"""Run every benchmark in one process and rewrite benchmarks/RESULTS.md.

    python benchmarks/run.py                 # about 5 minutes on 2 cores
    python benchmarks/run.py km wrinkles     # only some
    python benchmarks/run.py --device gradients limits --quick --results /tmp/R.md

Each benchmark prints its tables and replaces its own section of RESULTS.md (with the
machine, the device and the command); the order below runs the cheap, foundational ones
first. `--device` prints the device JAX measures on (platform, kind, count) before anything
runs; every section records it too. `--results PATH` writes the sections to PATH instead
of RESULTS.md (the GPU check writes under $OUT). `--quick` and `--repeat N` are passed to
the benchmarks that take them (wrinkles, gradients, limits).
"""

from __future__ import annotations

import argparse
import importlib
import inspect
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))

BENCHMARKS = {
    "stability": "stability",  # non-finite counts, float32 vs float64
    "km": "bench_km",  # KM layering, calibration, spectral grids
    "brdf": "bench_brdf",  # the Lafortune fit against SciPy
    "wrinkles": "bench_wrinkles",  # the furrow program against NumPy
    "render": "bench_render",  # shading and views, gradient, sweeps
    "sss": "bench_sss",  # the skin profile blur: error against time
    "makeup": "bench_makeup",  # cosmetics: frame, gradient, grids, the RGB shortcut
    "gradients": "bench_gradients",  # gradient / forward for every render model
    "limits": "limits",  # each hot stage against a memory pass and peak arithmetic
}


def main(argv: list[str]) -> int:
    ap = argparse.ArgumentParser(prog="run.py", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("names", nargs="*", metavar="NAME",
                    help=f"benchmarks to run, in this order (default: all): "
                         f"{', '.join(BENCHMARKS)}")
    ap.add_argument("--device", action="store_true",
                    help="print the device JAX measures on (its default one) before anything "
                         "runs; it chooses nothing: JAX_PLATFORMS=cpu or cuda does")
    ap.add_argument("--results", type=Path, help="write the sections to this file")
    ap.add_argument("--quick", action="store_true",
                    help="tiny sizes (a check that it runs), where supported")
    ap.add_argument("--repeat", type=int, help="timed repeats, where supported")
    opts = ap.parse_args(argv)
    names = opts.names or list(BENCHMARKS)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        print(f"run.py: unknown benchmark {unknown[0]!r}; choose from {', '.join(BENCHMARKS)}",
              file=sys.stderr)
        return 2
    import common

    if opts.device:
        print(f"device: {common.device()}", flush=True)
    if opts.results:
        common.RESULTS = opts.results
    passed = (["--quick"] if opts.quick else []) + (
        ["--repeat", str(opts.repeat)] if opts.repeat else []) + (
        ["--results", str(opts.results)] if opts.results else [])
    for name in names:
        print(f"\n=== {name} ===", flush=True)
        t0 = time.perf_counter()
        bench = importlib.import_module(BENCHMARKS[name]).main
        bench(passed) if inspect.signature(bench).parameters else bench()
        print(f"=== {name}: {time.perf_counter() - t0:.0f} s ===", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
