"""Shared helpers for the benchmark scripts: timing, machine description, RESULTS.md sections."""

from __future__ import annotations

import os
import platform
import re
import statistics
import sys
import time
from pathlib import Path

import jax
import numpy as np

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "RESULTS.md"


def timeit(fn, *args, repeat: int = 5, warmup: int = 1) -> float:
    """Best wall time in seconds of `fn(*args)` after `warmup` calls (results blocked on)."""
    for _ in range(warmup):
        jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
    return min(times)


def cold_and_warm(make_fn, *args, repeat: int = 5) -> tuple[float, float]:
    """(first call including tracing and compilation, best warm call) of a freshly jitted fn."""
    fn = make_fn()
    t0 = time.perf_counter()
    jax.block_until_ready(fn(*args))
    cold = time.perf_counter() - t0
    return cold, timeit(fn, *args, repeat=repeat, warmup=0)


def median_time(fn, repeat: int = 5) -> float:
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def srgb_lab(rgb, encoded: bool = False):
    """CIELAB (D65) of sRGB values: linear light (clipped at 0), or display values
    (`encoded`, clipped to [0, 1] and decoded), as the renderer writes them."""
    import colour

    srgb = colour.RGB_COLOURSPACES["sRGB"]
    rgb = np.clip(rgb, 0, 1) if encoded else np.clip(rgb, 0, None)
    xyz = colour.RGB_to_XYZ(rgb, srgb, apply_cctf_decoding=encoded)
    return colour.XYZ_to_Lab(xyz, srgb.whitepoint)


def machine() -> str:
    cpu = platform.processor() or "unknown CPU"
    try:
        text = Path("/proc/cpuinfo").read_text()
        cpu = re.search(r"model name\s*:\s*(.*)", text).group(1)
        flags = re.search(r"flags\s*:\s*(.*)", text).group(1).split()
        isa = "AVX-512" if "avx512f" in flags else ("AVX2" if "avx2" in flags else "SSE")
        cpu += f", {isa}"
    except (OSError, AttributeError):
        pass
    mem = ""
    try:
        kb = int(re.search(r"MemTotal:\s*(\d+)", Path("/proc/meminfo").read_text()).group(1))
        mem = f", {kb / 2**20:.0f} GiB"
    except (OSError, AttributeError):
        pass
    return (f"{cpu}, {os.cpu_count()} cores{mem}; Python {platform.python_version()}, "
            f"JAX {jax.__version__} on {jax.default_backend().upper()} ({device()})")


def device() -> str:
    """The device JAX computes on: platform, kind and how many, e.g. `gpu: NVIDIA H200 (1)`."""
    devices = jax.devices()
    return f"{devices[0].platform}: {devices[0].device_kind} ({len(devices)})"


def write_section(name: str, body: str) -> None:
    """Replace (or append) the section `name` of RESULTS.md between its markers."""
    start, end = f"<!-- {name}:start -->", f"<!-- {name}:end -->"
    text = RESULTS.read_text() if RESULTS.exists() else "# Benchmark results\n"
    block = f"{start}\n{body.rstrip()}\n{end}"
    if start in text:
        text = re.sub(re.escape(start) + ".*?" + re.escape(end), lambda _: block, text, flags=re.S)
    else:
        text = text.rstrip() + "\n\n" + block + "\n"
    tmp = RESULTS.with_suffix(".md.tmp")
    tmp.write_text(text)
    os.replace(tmp, RESULTS)


def table(headers, rows) -> str:
    out = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    out += ["| " + " | ".join(str(c) for c in row) + " |" for row in rows]
    return "\n".join(out)


def synthetic_measurement(rows: int, noise: float = 0.002, seed: int = 0):
    """foundation_beige's true S, K on `rows` bands over 380–780 nm, two thin layers over a
    black card, Gaussian noise σ = `noise`: a spectroradiometer export at its resolution."""
    sys.path.insert(0, str(HERE.parent / "data"))
    import make_measurements

    from jaxskin.fitting.measurements import Measurement

    wl = np.linspace(380.0, 780.0, rows)
    S0, K0 = make_measurements.true_spectra("foundation_beige")
    S, K = np.interp(wl, make_measurements.WL, S0), np.interp(wl, make_measurements.WL, K0)
    Rg = np.full(rows, 0.04)
    R, R_inf = make_measurements.simulate(S, K, [0.05, 0.15], Rg)
    rng = np.random.default_rng(seed)
    R = np.clip(R + rng.normal(0, noise, R.shape), 0, 1)
    R_inf = np.clip(R_inf + rng.normal(0, noise, rows), 0, 1)
    return Measurement(Path(f"synthetic_{rows}.csv"), f"synthetic_{rows}", wl,
                       np.array([0.05, 0.15]), R, R_inf, Rg, ("R_0.05mm", "R_0.15mm"), 1)


def save_figure(fig, path: Path) -> None:
    """Write a matplotlib figure as a PNG (atomically), close it and say where it went."""
    import matplotlib.pyplot as plt

    from jaxskin.io import atomic_write

    with atomic_write(path, "wb") as fh:
        fig.savefig(fh, format="png")
    plt.close(fig)
    print(f"wrote {path} ({path.stat().st_size // 1024} KB)")


def command(script: str, argv: list[str] | None) -> str:
    """The command line that made a section, for its "Command:" line: `python SCRIPT` and
    its options, less `--results FILE` (where the section was written, not how)."""
    words, skip = [], False
    for a in argv or []:
        if skip:
            skip = False
        elif a == "--results":
            skip = True
        elif not a.startswith("--results="):
            words.append(a)
    return " ".join(["python", script, *words])


def options(doc: str, argv: list[str] | None = None, more=None):
    """The options `run.py` passes on (`--quick`, `--repeat`, `--results`), parsed for a
    benchmark whose help is its docstring `doc`; `--results` redirects `write_section`.
    `more(parser)`, if given, adds the benchmark's own options."""
    import argparse

    global RESULTS
    ap = argparse.ArgumentParser(description=doc,  # the docstring: what it measures, how
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="tiny sizes (a check that it runs)")
    ap.add_argument("--repeat", type=int, default=5,
                    help="timed repeats where the benchmark takes them (default 5; what a "
                         "repeat is, each benchmark's docstring says)")
    ap.add_argument("--results", type=Path, help="write the section to this file instead")
    if more:
        more(ap)
    args = ap.parse_args(argv or [])
    if args.results:
        RESULTS = args.results
        RESULTS.parent.mkdir(parents=True, exist_ok=True)
    return args
