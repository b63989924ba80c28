"""Shared test fixtures.

`x64` gives a test float64 (gradient checks, reference comparisons) through
`jax.enable_x64(True)`, a context that ends with the test: the library's float32 default for
rendering is never changed globally.
"""

import atexit
import contextlib
import gc
import os
import shutil
import tempfile
from pathlib import Path

# XLA:CPU's element-wise code generator for fusions instead of its newer fusion emitters:
# about 40 % less compile time for the same run time (the makeup render's value and
# gradient at -O0: 5.1-5.6 -> 3.2 s; test_stability and test_makeup 133 -> 86 s of CPU),
# and the suite mostly compiles. Set before JAX starts its CPU backend; the commands tests
# start inherit it. Values can differ from a user's by float32 rounding (XLA fuses
# differently), so a test that compares with a user's exact bytes runs them in a process
# of their own (`user_process` below). JAXSKIN_TEST_OPTIMISE=1 compiles as users do.
if os.environ.get("JAXSKIN_TEST_OPTIMISE", "") in ("", "0"):
    os.environ["XLA_FLAGS"] = (f"{os.environ.get('XLA_FLAGS', '')} "
                               "--xla_cpu_use_fusion_emitters=false").strip()  # EMITTERS

import jax  # noqa: E402

EMITTERS = "--xla_cpu_use_fusion_emitters=false"


def assert_same_bytes(got, expected, what=""):
    """8-bit images `got` and `expected` (two programs' renders of one view: the editor's
    and `jaxskin render`'s) are equal. Under the suite's fusion emitters (`EMITTERS`) two
    programs of different shapes can round a value on an 8-bit level's edge apart (seen once
    in a full run, a perspective turn in test_editor): there one level in at most 1 of 10,000
    values; compiled as users compile (`JAXSKIN_TEST_OPTIMISE=1`), equal."""
    got, expected = np.asarray(got, np.int64), np.asarray(expected, np.int64)
    if EMITTERS not in os.environ.get("XLA_FLAGS", ""):
        assert np.array_equal(got, expected), what
        return
    off = np.abs(got - expected)
    assert off.max() <= 1 and (off > 0).mean() <= 1e-4, (what, off.max(), (off > 0).sum())


def user_process(code: str) -> str:
    """Run the Python `code` in a process that compiles as a user's does (XLA's default
    fusion emitters), for a test of exact bytes; its standard output. The module's -O0
    setting (`_compile_fast`) is inherited."""
    import subprocess
    import sys
    flags = os.environ.get("XLA_FLAGS", "").replace(EMITTERS, "").strip()
    r = subprocess.run([sys.executable, "-c", code], env={**os.environ, "XLA_FLAGS": flags},
                       capture_output=True, text=True, timeout=600)
    assert r.returncode == 0, r.stderr
    return r.stdout
import numpy as np  # noqa: E402
import pytest  # noqa: E402

# One persistent compilation cache for the whole run, in a temporary folder: the xdist
# workers, the modules (whose in-memory programs `_free_compiled_programs` drops) and the
# commands tests run as subprocesses (JAXSKIN_CACHE_DIR) load a program another one already
# compiled instead of compiling it again, and nothing is written into the user's home. The
# process that makes the folder (the xdist controller, or the one process with -n 0)
# removes it at exit; its workers inherit the variable.
if "JAXSKIN_TEST_CACHE" not in os.environ:
    # A run killed (`timeout`'s SIGTERM) runs no atexit: its folder, named by its process,
    # is removed by the next run once that process is gone (each holds some 30 MB).
    for stale in Path(tempfile.gettempdir()).glob("jaxskin-test-cache-*-*"):
        pid = stale.name.split("-")[3]
        try:
            os.kill(int(pid), 0)
        except ProcessLookupError:
            shutil.rmtree(stale, ignore_errors=True)
        except (ValueError, OSError):
            pass
    os.environ["JAXSKIN_TEST_CACHE"] = tempfile.mkdtemp(
        prefix=f"jaxskin-test-cache-{os.getpid()}-")
    atexit.register(shutil.rmtree, os.environ["JAXSKIN_TEST_CACHE"], ignore_errors=True)
os.environ["JAXSKIN_CACHE_DIR"] = os.environ["JAXSKIN_TEST_CACHE"]
jax.config.update("jax_compilation_cache_dir", os.environ["JAXSKIN_TEST_CACHE"])
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.1)
jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)

# pyproject's addopts run the suite as `-n auto --dist loadfile` (pytest-xdist): one worker
# process per core, a module's tests in one worker. Two workers on 2 cores peaked at 7.7 GB
# together (2026-12-03, sampled every 2 s; the commands the tests run as subprocesses
# included): WORKER_GB leaves room above that.
MAX_WORKERS, WORKER_GB = 4, 4.5


def pytest_xdist_auto_num_workers(config):
    """How many workers `-n auto` starts: one per core this process may use, at most
    MAX_WORKERS and at most one per WORKER_GB of available memory; 0 (the tests run in this
    process, no workers) where that leaves fewer than two."""
    cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count()
    n = min(cores or 1, MAX_WORKERS)
    try:
        with open("/proc/meminfo") as f:
            kb = next(int(line.split()[1]) for line in f if line.startswith("MemAvailable:"))
        n = min(n, int(kb / 2**20 // WORKER_GB))
    except (OSError, StopIteration, ValueError):
        pass  # not Linux: cores only
    return n if n >= 2 else 0


# The modules that take longest, longest first (summed test time on a quiet machine,
# 2026-12-07, with this branch's estimates for test_fit_image, test_docs, test_cli,
# test_readme, test_brdf_fit and test_outputs; the docs build is one test of some 1.5 min):
# xdist's loadfile hands modules out in collection order, so these start first and the run
# ends on short ones, both workers busy to the end. A stale list costs time only; the rest
# follow in file order.
SLOW_MODULES = ["test_fit_image", "test_fast_gradients", "test_docs", "test_render",
                "test_makeup", "test_cluster", "test_stability", "test_fit_skin_instruments",
                "test_cli", "test_calibrate", "test_km", "test_cosmetics", "test_gradients",
                "test_fit_skin", "test_wrinkles", "test_lockstep", "test_brdf_fit",
                "test_mixing", "test_readme", "test_bump_frames", "test_cards", "test_editor",
                "test_outputs"]


def pytest_collection_modifyitems(config, items):
    """The slow modules first (`SLOW_MODULES`); each module's tests keep their order."""
    rank = {name: i for i, name in enumerate(SLOW_MODULES)}
    items.sort(key=lambda item: rank.get(item.path.stem, len(rank)))


@pytest.fixture(autouse=True, scope="session")
def _no_persistent_cache_in_process():
    """`main()` called in-process would switch JAX's persistent compilation cache on for the
    rest of the session (a global setting); commands run as subprocesses still use it, and
    `test_persistent_compilation_cache` checks it there. Session-scoped: module fixtures
    (e.g. test_fit_skin's `fitted`) call `main()` before any function fixture is set up."""
    with pytest.MonkeyPatch.context() as mp:
        mp.setattr("jaxskin.compile_cache.enable", lambda: None)
        yield


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_programs():
    """Each compiled XLA:CPU program holds a few memory mappings until JAX's caches drop it;
    the whole suite in one process once passed Linux's 65,530 (vm.max_map_count) in
    test_makeup and crashed compiling (SIGSEGV, or SIGABRT in the compilation cache). Freed
    after each module: the count then stays near one module's programs."""
    yield
    jax.clear_caches()
    gc.collect()


# Most modules compile far longer than they run (small sizes, many distinct programs): for
# them XLA's optimisations cost more than they save. `jax_disable_most_optimizations` (LLVM at
# -O0 without its expensive passes; XLA's own graph passes still run) halves their compile
# time (2026-12-07, one process on 2 busy cores: test_fast_gradients' GPU-form tests 97 ->
# 50 s; test_stability, test_lockstep, test_wrinkles, test_shadow, test_scenes_look 265 ->
# 151 s). The modules listed here run large programs, or small ones many times (fits), and
# keep the optimising compiler, as do the commands their tests start: the golden images'
# renders 37 -> 74 s without it, test_cosmetic_colours 17 -> 39 s, the docs build 97 -> 138 s
# of CPU, three fit-image and fit-brdf tests 42 -> 73 s. The tolerances hold either way
# (the golden images pass at -O0 too). JAXSKIN_TEST_OPTIMISE=1 compiles every test as a
# user's run does. A test that runs far longer than it compiles, in a module that mostly
# compiles, is marked `optimised` instead (`_compile_optimised`): test_fit_image at -O0
# with its two scalar fits at 64² marked, 2026-12-07 (CPU seconds, one process, 2 busy
# cores): 18 of its other tests 288 -> 214 s, the two marked 47 -> 28 s.
OPTIMISED_MODULES = {"test_golden", "test_cosmetic_colours", "test_docs", "test_brdf_fit"}


@contextlib.contextmanager
def _optimisations(on: bool):
    """XLA's optimisations on or off while the context lasts: in-process (JAX's flag, read
    at each compile) and in the commands started meanwhile (the variable)."""
    before = os.environ.get("JAX_DISABLE_MOST_OPTIMIZATIONS")
    was = jax.config.read("jax_disable_most_optimizations")
    os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"] = "0" if on else "1"
    jax.config.update("jax_disable_most_optimizations", not on)
    try:
        yield
    finally:
        jax.config.update("jax_disable_most_optimizations", was)
        if before is None:
            os.environ.pop("JAX_DISABLE_MOST_OPTIMIZATIONS", None)
        else:
            os.environ["JAX_DISABLE_MOST_OPTIMIZATIONS"] = before


@pytest.fixture(autouse=True, scope="module")
def _compile_fast(request):
    """Compile this module's programs unoptimised unless it is in OPTIMISED_MODULES."""
    fast = (request.module.__name__.rsplit(".", 1)[-1] not in OPTIMISED_MODULES
            and os.environ.get("JAXSKIN_TEST_OPTIMISE", "") in ("", "0"))
    with _optimisations(not fast):
        yield


def pytest_configure(config):
    config.addinivalue_line(
        "markers", "optimised: compile this test's programs with XLA's optimisations in a "
        "module that compiles unoptimised (a test that runs its programs far longer than it "
        "compiles them)")


@pytest.fixture(autouse=True)
def _compile_optimised(request):
    """A test marked `optimised` compiles its programs (and its commands theirs) with XLA's
    optimisations, as OPTIMISED_MODULES do. A program compiled earlier in the module is
    reused as it was compiled: jit's in-memory cache does not key on the flag."""
    if request.node.get_closest_marker("optimised") is None:
        yield
        return
    with _optimisations(True):
        yield


_CACHE_DIR = jax.config.jax_compilation_cache_dir  # the run's folder, set above


@pytest.fixture(autouse=True)
def _cache_stays_off():
    # Tests run in-process keep to the run's cache folder (never the user's home).
    yield
    changed = jax.config.jax_compilation_cache_dir != _CACHE_DIR
    jax.config.update("jax_compilation_cache_dir", _CACHE_DIR)  # later tests start clean
    assert not changed, "a test switched the persistent cache on"


@pytest.fixture
def x64():
    with jax.enable_x64(True):
        yield


@pytest.fixture(scope="module")
def three_materials():
    """The shipped foundation, blush and lipstick on a 20 nm grid: `(grid, S, K)`, `(3, n)`."""
    from jaxskin import cosmetics, spectral

    grid = spectral.Grid(step=20)
    ms = [cosmetics.load_material(n, grid) for n in ("foundation_beige", "blush_rose",
                                                     "lipstick_red")]
    return grid, np.stack([m.S for m in ms]), np.stack([m.K for m in ms])


def check_grads_scaled(f, args, scales, order=2, eps=1e-5, **kw):
    """`jax.test_util.check_grads` in scaled coordinates: argument i is `args[i] + scales[i]·δᵢ`,
    checked at δ = 0, so one finite-difference step suits arguments of any magnitude (S ≈ 2
    beside X = 5000 or X = 5e-7). Fwd and rev, float64 (use with the `x64` fixture)."""
    import jax.numpy as jnp
    from jax.test_util import check_grads

    args = [jnp.asarray(a, jnp.float64) for a in args]
    scales = [jnp.asarray(s, jnp.float64) for s in scales]

    def g(*d):
        return f(*(a + s * x for a, s, x in zip(args, scales, d, strict=True)))

    check_grads(
        g, [jnp.zeros_like(a) for a in args], order=order, modes=("fwd", "rev"), eps=eps, **kw
    )
