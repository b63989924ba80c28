"""Run every benchmark in one process and rewrite benchmarks/RESULTS.md.

    python benchmarks/run.py                 # about 5 minutes on 2 cores
    python benchmarks/run.py km wrinkles     # only some

Each benchmark prints its tables and replaces its own section of RESULTS.md (with the
machine and the command); the order below runs the cheap, foundational ones first.
"""

from __future__ import annotations

import importlib
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
    "limits": "limits",  # each hot stage against a memory pass and peak arithmetic
}


def main(argv: list[str]) -> int:
    names = argv or list(BENCHMARKS)
    unknown = [n for n in names if n not in BENCHMARKS]
    if unknown:
        print(f"run.py: unknown benchmark {unknown[0]!r}; choose from {', '.join(BENCHMARKS)}",
              file=sys.stderr)
        return 2
    for name in names:
        print(f"\n=== {name} ===", flush=True)
        t0 = time.perf_counter()
        importlib.import_module(BENCHMARKS[name]).main()
        print(f"=== {name}: {time.perf_counter() - t0:.0f} s ===", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
