"""Kubelka–Munk benchmarks: texture layering, calibration, spectral grids (error against time).

    python benchmarks/bench_km.py            # about 3–4 minutes on 2 cores
    python benchmarks/bench_km.py scaling    # only the calibrate scaling (about a minute)

Prints tables, writes benchmarks/km_error_vs_time.png and the `km` section of
benchmarks/RESULTS.md. Every time is warm (after a call that compiled) unless it says cold;
results are blocked on; nothing is retraced inside a timing loop.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import colour
import jax
import jax.numpy as jnp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import (  # noqa: E402
    HERE,
    cold_and_warm,
    machine,
    median_time,
    synthetic_measurement,
    table,
    timeit,
    write_section,
)

from jaxskin import formats, km, spectral  # noqa: E402
from jaxskin.fitting import km as fit_km  # noqa: E402
from jaxskin.fitting.measurements import read_measurement  # noqa: E402
from jaxskin.io import data_dir  # noqa: E402

ROOT = HERE.parent
MATERIALS = ("foundation_beige", "blush_rose", "lipstick_red")


# ---------------------------------------------------------------- inputs


def load_materials(wavelengths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """S, K (3, n) of the shipped example materials, interpolated in log onto `wavelengths`."""
    S, K = [], []
    for name in MATERIALS:
        doc = json.loads((data_dir() / "materials" / f"{name}.json").read_text())
        wl = np.asarray(doc["wavelength_nm"])
        S.append(np.exp(np.interp(wavelengths, wl, np.log(doc["S_per_mm"]))))
        K.append(np.exp(np.interp(wavelengths, wl, np.log(doc["K_per_mm"]))))
    return np.array(S), np.array(K)


def skin_reflectance(wavelengths: np.ndarray) -> np.ndarray:
    """NIST subject 1's mean forearm reflectance, interpolated onto `wavelengths`."""
    return np.interp(wavelengths, *formats.nist_spectrum(1))


def thickness_maps(n: int, seed: int = 0) -> np.ndarray:
    """(3, n, n, 1) mm: foundation everywhere, a blush blob, a lipstick band; zeros included."""
    y, x = np.mgrid[0:n, 0:n] / n
    rng = np.random.default_rng(seed)
    foundation = 0.02 * (0.5 + 0.5 * np.sin(6 * x + rng.uniform()) * np.cos(5 * y))
    blush = 0.03 * np.exp(-((x - 0.3) ** 2 + (y - 0.5) ** 2) / 0.02)
    lipstick = 0.05 * ((np.abs(y - 0.8) < 0.08) & (np.abs(x - 0.5) < 0.25))
    return np.stack([foundation, blush, lipstick])[..., None]


# ---------------------------------------------------------------- pipelines


def over_skin(S, K, X, Rg):
    """Reflectance of the 3-layer stack over skin: what the renderer needs (one output)."""
    R, T = km.layer(S[:, None, None, :], K[:, None, None, :], X)
    s = km.stack(R, T)
    return km.over(s.R, s.T, Rg, s.R_back)


def naive_layer(S, K, X, xp=jnp):
    """Huang et al. eq. 1–2 as printed: a = 1 + K/S, b = sqrt(a² − 1), sinh/cosh."""
    a = 1 + K / S
    b = xp.sqrt(a * a - 1)
    sh, ch = xp.sinh(b * S * X), xp.cosh(b * S * X)
    d = a * sh + b * ch
    return sh / d, b / d


def naive_over_skin(S, K, X, Rg, xp=jnp):
    """A straightforward transcription of Huang et al. eq. 1–2 and Kubelka's rule (corrected
    eq. 3–4): a = 1 + K/S, b = sqrt(a² − 1), sinh/cosh. Overflows for bSX > 89 (float32)."""
    R, T = naive_layer(S[:, None, None, :], K[:, None, None, :], X, xp)
    acc_R, acc_T, acc_Rb = Rg, xp.zeros_like(Rg), Rg
    for i in (2, 1, 0):
        inv = 1 / (1 - R[i] * acc_R)
        acc_R, acc_T, acc_Rb = (R[i] + T[i] ** 2 * acc_R * inv, T[i] * acc_T * inv,
                                acc_Rb + acc_T ** 2 * R[i] * inv)
    return acc_R


def texture_benchmark():
    n, grid = 1024, spectral.Grid(step=10)
    S, K = load_materials(grid.wavelengths)
    X = thickness_maps(n)
    Rg = skin_reflectance(grid.wavelengths)
    f32 = lambda a: jnp.asarray(a, jnp.float32)  # noqa: E731
    args = (f32(S), f32(K), f32(X), f32(Rg))

    def stack_part(part):
        def f(S, K, X):
            R, T = km.layer(S[:, None, None, :], K[:, None, None, :], X)
            return getattr(km.stack(R, T), part)
        return jax.jit(f)

    fR, fT = stack_part("R"), stack_part("T")

    def rt_one_program(S, K, X):
        R, T = km.layer(S[:, None, None, :], K[:, None, None, :], X)
        s = km.stack(R, T)
        return s.R, s.T

    rows = []
    cold, warm = cold_and_warm(lambda: jax.jit(over_skin), *args)
    rows.append(("ours: 3 layers over skin (1 output)", warm, cold))
    cold, warm = cold_and_warm(lambda: fR, *args[:3])
    rows.append(("ours: stack R only", warm, cold))
    rows.append(("ours: stack R and T, two programs",
                 timeit(lambda *a: (fR(*a), fT(*a)), *args[:3]), None))
    cold, warm = cold_and_warm(lambda: jax.jit(rt_one_program), *args[:3], repeat=2)
    rows.append(("ours: stack R and T, one program (XLA:CPU materialises)", warm, cold))
    cold, warm = cold_and_warm(lambda: jax.jit(naive_over_skin), *args)
    rows.append(("baseline: paper's sinh/cosh form, jitted", warm, cold))
    np_args = [np.asarray(a) for a in args]
    t0 = time.perf_counter()
    naive_over_skin(*np_args, xp=np)
    rows.append(("baseline: same in NumPy float32", time.perf_counter() - t0, None))
    out_bytes = n * n * len(grid) * 4
    fill = jax.jit(lambda X: X[0] * jnp.ones(len(grid), jnp.float32))
    rows.append((f"limit: write the output once ({out_bytes / 2**20:.0f} MiB)",
                 timeit(fill, args[2]), None))

    ours = rows[0][1]
    table_rows = [(name, f"{warm * 1e3:.0f}", "" if cold is None else f"{cold:.2f}",
                   f"{warm / ours:.2f}") for name, warm, cold in rows]

    # float32 against float64, and the baseline's failures on the same texture.
    with jax.enable_x64(True):
        ref = np.asarray(jax.jit(over_skin)(*(jnp.asarray(a, jnp.float64) for a in (S, K, X, Rg))))
        assert ref.dtype == np.float64
    got = np.asarray(jax.jit(over_skin)(*args))
    err32 = np.abs(got - ref)
    naive = np.asarray(jax.jit(naive_over_skin)(*args))
    return {
        "n": n, "bands": len(grid), "table": table_rows,
        "f32_max_abs": float(err32.max()), "f32_max_rel": float((err32 / ref).max()),
        "naive_max_abs": float(np.nanmax(np.abs(naive - ref))),
        "naive_nonfinite": int(np.sum(~np.isfinite(naive))),
    }


def extreme_baseline_check():
    """Where the paper's form breaks: non-finite values of the baseline vs ours (float32)."""
    S = jnp.asarray([[1.0, 10.0, 1.0]], jnp.float32)
    K = jnp.asarray([[0.0, 0.5, 1e-8]], jnp.float32)
    X = jnp.asarray([1.0, 40.0, 1.0], jnp.float32)  # bSX = 128 > 89 overflows cosh
    out = []
    for s, k, x in zip(S[0], K[0], X, strict=True):
        naive = tuple(float(v) for v in naive_layer(s, k, x))
        ours = tuple(float(v) for v in km.layer(s, k, x))
        out.append((f"S={float(s):g}, K={float(k):g}, X={float(x):g}", naive, ours))
    return out


# ---------------------------------------------------------------- calibration


def calibration_benchmark():
    path = data_dir() / "measurements" / "foundation_beige.csv"
    m = read_measurement(path)
    t0 = time.perf_counter()
    fit_km.fit(m)
    cold_in_process = time.perf_counter() - t0
    warm = median_time(lambda: fit_km.fit(m), repeat=5)

    def cli(env):
        with tempfile.TemporaryDirectory() as out:
            t0 = time.perf_counter()
            subprocess.run([sys.executable, "-m", "jaxskin.cli", "calibrate", str(path), "-o",
                            out, "--no-report"], check=True, env=env, capture_output=True)
            return time.perf_counter() - t0

    with tempfile.TemporaryDirectory() as cache:
        base = {**os.environ, "JAXSKIN_CACHE_DIR": cache}
        no_cache = cli({**base, "JAXSKIN_NO_COMPILE_CACHE": "1"})
        cli(base)  # fills the cache
        cached = cli(base)
    return {"bands": len(m.wavelength_nm), "thicknesses": len(m.thickness_mm), "warm": warm,
            "cold_in_process": cold_in_process, "cli_no_cache": no_cache, "cli_cached": cached}


# ---------------------------------------------------------------- calibration: scaling

SCALING_ROWS = (81, 1001, 10_001)  # 5 nm, 0.4 nm, 0.04 nm over 380–780 nm
DENSE_ROWS = (81,)  # the old dense solver, as the baseline, where it is still quick


_PEAK = """
import re, sys, time
sys.path.insert(0, {bench!r})
from common import synthetic_measurement
from jaxskin.fitting import km

def hwm():  # this process's peak resident memory, KiB (VmHWM: reset at exec, unlike ru_maxrss)
    return int(re.search(r"VmHWM:\\s*(\\d+)", open("/proc/self/status").read()).group(1))

m = synthetic_measurement({rows})
base = hwm()
t0 = time.perf_counter()
km.fit(m, smooth={smooth})
cold = time.perf_counter() - t0
print(base, hwm(), cold)
"""


def peak_memory(rows: int, smooth: float) -> tuple[float, float, float]:
    """(peak RSS MiB after imports and the data, peak RSS MiB after one fit, cold fit s) of
    a fresh process: the whole fit's peak, compilation included."""
    code = _PEAK.format(bench=str(HERE), rows=rows, smooth=smooth)
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True,
                         text=True).stdout.split()
    return int(out[0]) / 1024, int(out[1]) / 1024, float(out[2])


def cli_peak(rows: int, smooth: float) -> tuple[float, float] | None:
    """(wall s, peak RSS MiB) of `jaxskin calibrate` on a `rows`-band CSV, report PNG
    included, compilation cache warm, measured by /usr/bin/time -v (None without it)."""
    if not os.path.exists("/usr/bin/time"):
        return None
    m = synthetic_measurement(rows)
    with tempfile.TemporaryDirectory() as tmp:
        csv = Path(tmp) / f"{m.name}.csv"
        cols = np.column_stack([m.wavelength_nm, m.R.T, m.R_inf, m.R_g])
        np.savetxt(csv, cols, delimiter=",", fmt="%.6g", comments="",
                   header="wavelength_nm,R_0.05mm,R_0.15mm,R_inf,R_g")
        env = {**os.environ, "JAXSKIN_CACHE_DIR": str(Path(tmp) / "cache")}
        cmd = ["/usr/bin/time", "-v", sys.executable, "-m", "jaxskin.cli", "calibrate",
               str(csv), "-o", str(Path(tmp) / "out"), "--smooth", f"{smooth:g}"]
        subprocess.run(cmd, check=True, capture_output=True, env=env)  # fills the cache
        t0 = time.perf_counter()
        err = subprocess.run(cmd, check=True, capture_output=True, env=env, text=True).stderr
        wall = time.perf_counter() - t0
    kib = int(re.search(r"Maximum resident set size \(kbytes\): (\d+)", err).group(1))
    return wall, kib / 1024


def calibration_scaling():
    """Warm fit time against the number of bands, banded (per-band / block-tridiagonal)
    against the old dense solver where it is quick, and the peak memory of a fresh process
    at 10,001 bands. Warm: after a call that compiled; the result is a host array (blocked
    on); the jitted solvers' caches are checked not to grow inside the timing loop."""
    rows_out = []
    for rows in SCALING_ROWS:
        m = synthetic_measurement(rows)
        for smooth in (0.0, 20.0):
            fit_km.fit(m, smooth=smooth)  # compile
            solver = fit_km._solve_coupled if smooth else fit_km._solve_separable
            cached = solver._cache_size()
            warm = median_time(lambda m=m, smooth=smooth: fit_km.fit(m, smooth=smooth), 3)
            assert solver._cache_size() == cached, "retraced inside the timing loop"
            dense = None
            if rows in DENSE_ROWS:
                fit_km.fit(m, smooth=smooth, solver="dense")
                dense = median_time(
                    lambda m=m, smooth=smooth: fit_km.fit(m, smooth=smooth, solver="dense"), 3)
            r = fit_km.fit(m, smooth=smooth)
            rows_out.append((rows, smooth, warm, dense, r.steps, r.converged))
    rows_out.sort()
    peaks = {smooth: (*peak_memory(SCALING_ROWS[-1], smooth), cli_peak(SCALING_ROWS[-1], smooth))
             for smooth in (0.0, 20.0)}
    return rows_out, peaks, os.getloadavg()[0]


def scaling_section(rows_out, peaks, load) -> str:
    t = table(["bands", "--smooth", "banded warm s", "dense warm s", "dense / banded", "steps",
               "converged"],
              [(n, f"{s:g}", f"{w:.3f}", "" if d is None else f"{d:.3f}",
                "" if d is None else f"{d / w:.1f}", k, c) for n, s, w, d, k, c in rows_out])
    p = table(["--smooth", "peak MiB: imports + data", "peak MiB: after the fit",
               "cold fit s (compiling)", "CLI s, cache warm, with report", "CLI peak MiB"],
              [(f"{s:g}", f"{a:.0f}", f"{b:.0f}", f"{c:.1f}",
                *(("", "") if cli is None else (f"{cli[0]:.1f}", f"{cli[1]:.0f}")))
               for s, (a, b, c, cli) in peaks.items()])
    return f"""## Calibration scaling (issue 13)

Command: `python benchmarks/bench_km.py scaling`. Machine: {machine()}; load average
{load:.1f} during the run (other work shared the 2 cores: read the times with that in mind).

`fitting.km.fit` on foundation_beige's true spectra resampled to N bands over 380–780 nm
(two thin layers, black card, σ = 0.002 noise). "banded": without the prior, a
Levenberg–Marquardt per band, vmapped; with it (`--smooth 20`), one Levenberg–Marquardt whose
normal equations are block-tridiagonal (2×2 blocks), solved by block elimination in a scan.
"dense": the solver before issue 13, optimistix's Levenberg–Marquardt with a dense Jacobian
over all bands, (m + 1) N × 2N, kept as `fit(..., solver="dense")`; it is timed only where
it is still quick (it needed 27 GB at 10,001 bands). Warm times, median of 3.

{t}

Peak memory of a fresh process fitting {SCALING_ROWS[-1]:,} bands (VmHWM from
/proc/self/status; JAX's own import is most of it), and the whole command
`jaxskin calibrate` on a {SCALING_ROWS[-1]:,}-row CSV (reading, fit, JSON, PNG report; its
compilation cache warm; `/usr/bin/time -v`):

{p}

Aim (issue 13): 10,001 rows under 10 s warm and under 1 GiB peak, with and without the prior.

Reading: the banded fit's time grows linearly with the number of bands (well under a
second at 10,001) and its memory is O(N) (the fit adds under 200 MiB at 10,001 bands,
compilation included; a separate run at 100,001 bands peaked at 458–484 MiB, about 0.5 KB
per band above the 10,001-band figure), against the dense Jacobian's O(N²). Its results
match the dense solver's on the shipped examples to 5.5e-9 relative in S and K
(`tests/test_calibrate.py`).
The dense warm times here are far above the 0.027 s the `km` section measured on a quieter
machine: this run shared the 2 cores with other work, and the dense solve suffered far more
from that than the banded one; read its ratio as "orders of magnitude", not as a precise
figure.
"""


# ---------------------------------------------------------------- error against time


def lab(XYZ):
    white = colour.CCS_ILLUMINANTS["CIE 1931 2 Degree Standard Observer"]["D65"]
    return colour.XYZ_to_Lab(np.asarray(XYZ, np.float64), white)


def spectral_error_vs_time(n: int = 512):
    X = thickness_maps(n, seed=1)
    fine = spectral.Grid(step=1)
    S1, K1 = load_materials(fine.wavelengths)
    skin1 = skin_reflectance(fine.wavelengths)

    def spectral_xyz(grid):
        idx = np.searchsorted(fine.wavelengths, grid.wavelengths)
        W = jnp.asarray(grid.xyz_matrix)

        def f(S, K, X, Rg):
            return over_skin(S, K, X, Rg) @ W.astype(S.dtype)

        return jax.jit(f), (S1[:, idx], K1[:, idx], X, skin1[idx])

    def rgb_km(grid):
        """Huang et al.'s shortcut: each layer's R0 and T to RGB first, then layer in RGB."""
        idx = np.searchsorted(fine.wavelengths, grid.wavelengths)
        M = jnp.asarray(grid.rgb_matrix)
        to_xyz = jnp.asarray(np.linalg.inv(np.asarray(
            colour.RGB_COLOURSPACES["sRGB"].matrix_XYZ_to_RGB)).T)

        def f(S, K, X, Rg):
            R, T = km.layer(S[:, None, None, :], K[:, None, None, :], X)
            R_rgb, T_rgb = R @ M.astype(S.dtype), T @ M.astype(S.dtype)
            s = km.stack(R_rgb, T_rgb)
            return km.over(s.R, s.T, Rg @ M.astype(S.dtype), s.R_back) @ to_xyz.astype(S.dtype)

        return jax.jit(f), (S1[:, idx], K1[:, idx], X, skin1[idx])

    with jax.enable_x64(True):
        f, a = spectral_xyz(fine)
        reference = lab(f(*(jnp.asarray(v, jnp.float64) for v in a)))

    rows = []
    for label, make in [("spectral 1 nm", lambda: spectral_xyz(fine)),
                        ("spectral 5 nm", lambda: spectral_xyz(spectral.Grid(step=5))),
                        ("spectral 10 nm", lambda: spectral_xyz(spectral.Grid(step=10))),
                        ("spectral 20 nm", lambda: spectral_xyz(spectral.Grid(step=20))),
                        ("RGB KM (paper), 10 nm", lambda: rgb_km(spectral.Grid(step=10))),
                        ("RGB KM (paper), 5 nm", lambda: rgb_km(spectral.Grid(step=5)))]:
        f, a = make()
        a = [jnp.asarray(v, jnp.float32) for v in a]
        t = timeit(f, *a, repeat=3)
        dE = np.asarray(colour.delta_E(lab(f(*a)), reference, method="CIE 2000"))
        rows.append((label, t, float(dE.mean()), float(np.percentile(dE, 99)), float(dE.max())))
    return n, rows


def plot(rows, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 4.2), constrained_layout=True)
    for label, t, mean, p99, _ in rows:
        marker = "s" if "RGB" in label else "o"
        ax.loglog(t * 1e3, max(p99, 1e-4), marker, ms=8, label=f"{label} (p99)")
        colour_ = ax.lines[-1].get_color()
        ax.loglog(t * 1e3, max(mean, 1e-4), marker, ms=5, mfc="none", color=colour_)
        if label == "spectral 5 nm":
            ax.annotate("Grid() default", (t * 1e3, p99), textcoords="offset points",
                        xytext=(8, 8))
        if label == "spectral 10 nm":
            ax.annotate("scenes' default (spectral.step)", (t * 1e3, p99),
                        textcoords="offset points", xytext=(8, -12))
    ax.axhline(1.0, color="k", lw=0.6, ls=":")
    ax.text(ax.get_xlim()[0] * 1.1, 1.08, "ΔE2000 = 1 (just noticeable)", fontsize=7)
    ax.set(xlabel="warm time per 512² frame, 3 layers (ms)", ylabel="ΔE2000 vs 1 nm float64",
           title="Cosmetic layering: colour error against run time\n"
           "(filled: 99th percentile, hollow: mean; 1e-4 = floor)")
    ax.legend(fontsize=7)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main():
    if sys.argv[1:] == ["scaling"]:
        section = scaling_section(*calibration_scaling())
        print(section)
        write_section("km-scaling", section)
        return
    print(machine())
    tex = texture_benchmark()
    print(f"\nKM layer + stack, {tex['n']}² texture × {tex['bands']} bands × 3 layers, float32")
    t1 = table(["variant", "warm ms", "cold s", "× ours"], tex["table"])
    print(t1)
    cal = calibration_benchmark()
    print("\ncalibration:", cal)
    n, err_rows = spectral_error_vs_time()
    t3 = table(["variant", "warm ms", "mean ΔE2000", "p99 ΔE2000", "max ΔE2000"],
               [(r[0], f"{r[1] * 1e3:.0f}", f"{r[2]:.3f}", f"{r[3]:.3f}", f"{r[4]:.3f}")
                for r in err_rows])
    print(t3)
    plot(err_rows, HERE / "km_error_vs_time.png")
    ext = extreme_baseline_check()
    t4 = table(["inputs", "paper's form (R0, T)", "ours (R0, T)"],
               [(a, f"{b[0]:.4g}, {b[1]:.4g}", f"{c[0]:.4g}, {c[1]:.4g}") for a, b, c in ext])

    body = f"""## Kubelka–Munk (issue 3)

Command: `python benchmarks/bench_km.py`. Machine: {machine()}.

### Layer + stack over a texture

{tex['n']}² texture × {tex['bands']} bands (10 nm) × 3 layers (the shipped example materials),
thickness maps per layer, over the NIST skin spectrum; float32. "× ours" is the time over
the first row.

{t1}

float32 against float64 on the same texture: max abs error {tex['f32_max_abs']:.1e}, max
relative error {tex['f32_max_rel']:.1e}. The paper's sinh/cosh form on the same inputs:
max abs error {tex['naive_max_abs']:.1e}, {tex['naive_nonfinite']} non-finite values. Where
it breaks (float32):

{t4}

What the table says: the renderer's quantity (the stack over skin, one output) runs at
{tex['table'][0][1]} ms, within the 150 ms aim. Asking one XLA:CPU program for R *and* T
of the stack is the trap: XLA materialises the exp and the divisions shared by the two
outputs as full-size arrays (five of 516 MB here); two single-output programs are far
faster. Ask a jitted function for the outputs you need.

### Calibration (`jaxskin calibrate`)

`data/measurements/foundation_beige.csv`: {cal['bands']} bands, {cal['thicknesses']}
thicknesses.

| what | seconds |
|---|---|
| warm fit (median of 5, in process) | {cal['warm']:.3f} |
| first fit in process (trace + compile) | {cal['cold_in_process']:.2f} |
| CLI, whole process, compilation cache off | {cal['cli_no_cache']:.2f} |
| CLI, whole process, compilation cache warm | {cal['cli_cached']:.2f} |

### Spectral grid and the paper's RGB shortcut: error against run time

{n}² texture, 3 layers over skin, XYZ → CIELAB (D65); ΔE2000 against a 1 nm float64
reference. "RGB KM" is Huang et al.'s shortcut: each layer's R0 and T converted to RGB
first, then layered in RGB.

{t3}

![error against time](km_error_vs_time.png)

Reading: every spectral grid is far below ΔE2000 = 1; `Grid()` keeps the 5 nm default of
the paper's measurements, and 10 nm costs about half as much for no visible loss (the ASTM
E308 10 nm weights even land closer to the 1 nm sum here), so the cosmetics renderer can
use 10 nm. The paper's RGB shortcut is the only variant with visible error (p99 ≈ 1.8, in
the lipstick over foundation), and with thickness varying per texel it is not faster either:
the per-layer spectra must still be computed before they are converted.
"""
    write_section("km", body)
    write_section("km-scaling", scaling_section(*calibration_scaling()))
    print(f"\nwrote {HERE / 'RESULTS.md'} and {HERE / 'km_error_vs_time.png'}")


if __name__ == "__main__":
    main()
