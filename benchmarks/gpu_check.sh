#!/usr/bin/env bash
# The GPU check (issue 19): one script, at most 8 minutes on a GPU machine that reaches no
# package registry. It installs the wheels it lacks without dependencies, runs the
# gradient, furrow, derivative-form and limit benchmarks with reduced repeats and a chosen
# test subset in the time left, and writes everything under $OUT. It stops at once where
# JAX sees no GPU.
#
#   benchmarks/gpu_check.sh --download   # HERE, with a network: fill the wheel folder
#   benchmarks/gpu_check.sh              # on the GPU machine (carry benchmarks/_work)
#   benchmarks/gpu_check.sh --cpu        # the same end to end on the CPU, tiny sizes
#
# The wheel folder is benchmarks/_work/wheels (ignored by git; carry it, about 35 MB): for
# what the GPU machine did not have when last measured (JAX with CUDA, equinox, optimistix
# and lineax were there), the pure-Python wheels plus CPython 3.12 manylinux builds of
# matplotlib and its binaries. Only modules that do not import already are installed, into
# a folder outside the tree, so the machine's own JAX is kept. jaxskin itself is laid out
# there as pyproject.toml's package-dir does (jaxskin/, fitting/ as jaxskin/fitting, data/
# as jaxskin/data): always this tree's code, no build step. Tests and benchmarks run from a
# scratch copy without the source package, so that layout is the one imported. Each step
# has its own time limit; a failed step is recorded, not fatal.
#
# Output under $OUT (default /tmp/jaxskin_check_out): env.txt (Python, JAX, devices, what
# was installed), RESULTS.md (the benchmark sections: gradients, wrinkles-speed, limits),
# RESULTS_cpu_chunks.md (the gradients with the CPU's chunking), forms.txt (bench_forms.py's
# two lines), one log per step, tests.txt (pytest's summary line), summary.txt. The wheel
# folder is needed only where the machine cannot install from a package index: after
# `pip install -e '.[cuda13,test]'` (or `cuda12`) in a virtual environment,
# `PYTHON=.venv/bin/python benchmarks/gpu_check.sh` finds everything installed.
set -u
ROOT="${JAXSKIN_ROOT:-$(cd "$(dirname "$0")/.." && pwd)}"  # the repository
WHEELS="$ROOT/benchmarks/_work/wheels"
PY="${PYTHON:-python3}"
MODE=gpu
for arg in "$@"; do
  case "$arg" in
    --cpu) MODE=cpu ;;
    --download) MODE=download ;;
    -h|--help) sed -n '2,/^set -u/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
    *) echo "gpu_check.sh: unknown argument $arg (--cpu, --download or --help)" >&2; exit 2 ;;
  esac
done

if [ "$MODE" = download ]; then
  PIP="${PYTHON:-$ROOT/.venv/bin/python}"
  mkdir -p "$WHEELS"
  "$PIP" -m pip download -q --no-deps -d "$WHEELS" trimesh==5.2.0 colour-science==0.4.7 \
    imageio==2.38.1 jaxtyping==0.3.11 wadler-lindig tqdm==4.70.1 pypng==0.20220715.0 \
    mpmath==1.4.1 pytest==9.2.0 pluggy==1.7.0 iniconfig==2.3.1 cycler==0.12.1 \
    pytest-xdist==3.8.0 execnet==2.1.2 \
    pyparsing==3.3.3 packaging typing-extensions
  "$PIP" -m pip download -q --no-deps --only-binary=:all: --python-version 3.12 \
    --platform manylinux2014_x86_64 --platform manylinux_2_28_x86_64 -d "$WHEELS" \
    matplotlib==3.11.2 pillow==13.0.0 kiwisolver==1.5.1 contourpy==1.3.3 fonttools==4.68.0
  du -sh "$WHEELS"
  exit 0
fi

OUT="${OUT:-/tmp/jaxskin_check_out}"
mkdir -p "$OUT"
# this run's files only: an earlier run's sections and logs in $OUT would mix with them
rm -f "$OUT"/summary.txt "$OUT"/env.txt "$OUT"/RESULTS.md "$OUT"/RESULTS_cpu_chunks.md \
  "$OUT"/forms.txt "$OUT"/tests.txt "$OUT"/*.log
DEPS="$(mktemp -d /tmp/jaxskin_deps.XXXX)"
WORK="$(mktemp -d /tmp/jaxskin_work.XXXX)"
trap 'rm -rf "$DEPS" "$WORK"' EXIT
START=$(date +%s)
log() { echo "[$(( $(date +%s) - START )) s] $*" | tee -a "$OUT/summary.txt"; }

if [ "$MODE" = cpu ]; then
  export JAX_PLATFORMS=cpu
  PY="${PYTHON:-$ROOT/.venv/bin/python}"
  QUICK=--quick; REPEAT=2; LIMIT=400; TEST_LIMIT=900; TOTAL=3600; WORKERS=2
  SCENES=(camera.size=64 camera.height=64 texture.size=64)
else  # six benchmark steps of at most LIMIT, the tests in what is left of TOTAL
  QUICK=; REPEAT=3; LIMIT=80; TEST_LIMIT=240; TOTAL=480; WORKERS=8
  SCENES=()
fi

# 1. What the machine lacks, from the wheel folder, without dependencies.
cp -r "$ROOT/jaxskin" "$DEPS/jaxskin"
cp -r "$ROOT/fitting" "$DEPS/jaxskin/fitting"
cp -r "$ROOT/data" "$DEPS/jaxskin/data"
find "$DEPS" -name __pycache__ -prune -exec rm -rf {} +
missing=()
for pair in trimesh:trimesh colour:colour_science imageio:imageio jaxtyping:jaxtyping \
            wadler_lindig:wadler_lindig tqdm:tqdm png:pypng mpmath:mpmath pytest:pytest \
            xdist:pytest-xdist execnet:execnet \
            pluggy:pluggy iniconfig:iniconfig matplotlib:matplotlib PIL:pillow \
            kiwisolver:kiwisolver contourpy:contourpy fontTools:fonttools cycler:cycler \
            pyparsing:pyparsing packaging:packaging typing_extensions:typing_extensions; do
  module="${pair%%:*}"; dist="${pair##*:}"
  "$PY" -c "import $module" 2>/dev/null || missing+=("$dist")
done
if [ ${#missing[@]} -gt 0 ]; then
  log "installing without dependencies: ${missing[*]}"
  for dist in "${missing[@]}"; do  # one at a time: a wheel that does not fit stops no other
    "$PY" -m pip install -q --no-deps --no-index --find-links "$WHEELS" --target "$DEPS" \
      "$dist" >> "$OUT/install.log" 2>&1 || log "FAILED: no wheel for $dist here (install.log)"
  done
fi
export PYTHONPATH="$DEPS${PYTHONPATH:+:$PYTHONPATH}"
cp -r "$ROOT/benchmarks" "$ROOT/tests" "$ROOT/data" "$ROOT/pyproject.toml" "$WORK/"
rm -rf "$WORK/benchmarks/_work"
cd "$WORK" || exit 1
{ "$PY" -c "import sys, jax, jaxskin; print('Python', sys.version.split()[0]);
print('JAX', jax.__version__, jax.default_backend(), jax.devices());
print('jaxskin from', jaxskin.__file__)"; echo "installed: ${missing[*]:-nothing}"; \
  nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv 2>/dev/null; } \
  > "$OUT/env.txt" 2>&1
cat "$OUT/env.txt" | tee -a "$OUT/summary.txt"
if [ "$MODE" = gpu ] && ! "$PY" -c "import jax, sys; sys.exit(jax.default_backend() != 'gpu')"
then  # JAX would fall back to the CPU at full sizes: every step at its limit, no figures
  log "gpu_check.sh: JAX sees no GPU here (env.txt); on a CPU run it with --cpu"
  exit 2
fi

step() {  # step NAME LIMIT COMMAND...: run with a time limit, log under $OUT, record it
  local name=$1 limit=$2; shift 2
  local t0=$(date +%s)
  timeout -k 10 "$limit" "$@" > "$OUT/$name.log" 2>&1
  local rc=$?
  log "$name: exit $rc in $(( $(date +%s) - t0 )) s (limit $limit s)"
}

# 2. Benchmarks (reduced repeats), sections into $OUT/RESULTS.md, the most wanted first:
# the gradients (the device's chunking, then the CPU's for comparison, in its own process:
# the chunking is read when the derivative is traced, and jit keeps the first trace), the
# furrow programs' times, the derivative's forms, the limit lines. The frame check only with --cpu (the limit lines time the same renders).
RUN=("$PY" benchmarks/run.py --device --results "$OUT/RESULTS.md" --repeat "$REPEAT" $QUICK)
step gradients "$LIMIT" "${RUN[@]}" gradients
step furrows "$LIMIT" "$PY" benchmarks/bench_wrinkles.py --speed $QUICK --results "$OUT/RESULTS.md"
# the makeup derivative's forms: the device's (plain on a GPU) and XLA:CPU's, a process each
step forms_plain "$LIMIT" "$PY" benchmarks/bench_forms.py plain $QUICK
step forms_cpu "$LIMIT" "$PY" benchmarks/bench_forms.py cpu $QUICK
grep -h " forward " "$OUT/forms_plain.log" "$OUT/forms_cpu.log" > "$OUT/forms.txt"
step gradients_cpu_chunks "$LIMIT" "$PY" benchmarks/bench_gradients.py --chunking cpu \
  --repeat "$REPEAT" $QUICK --results "$OUT/RESULTS_cpu_chunks.md"
step limits "$LIMIT" "${RUN[@]}" limits
if [ "$MODE" = cpu ]; then
  step frames "$LIMIT" "$PY" benchmarks/frame_check.py ${SCENES[@]+"${SCENES[@]}"}
fi

# 3. Tests, in the time left (TOTAL in all): precision first, then golden images, colour
# references, KM and spectral conversion, the float64 gradient checks and the makeup
# derivative's rule, renders, the furrow programs. -v: each result is logged as it comes,
# so a run stopped at its limit still says what passed. Workers share the GPU, so JAX
# allocates as it goes rather than taking most of the memory up front.
left=$(( TOTAL - ($(date +%s) - START) - 10 ))
[ "$left" -gt "$TEST_LIMIT" ] && left=$TEST_LIMIT
export XLA_PYTHON_CLIENT_PREALLOCATE=false
if [ "$left" -lt 30 ]; then
  log "tests: not run, $left s left of the $TOTAL s"
else
  step tests "$left" "$PY" -m pytest -v -p no:cacheprovider -n "$WORKERS" --dist loadfile \
    -m "not slow" tests/test_precision.py tests/test_golden.py tests/test_references.py \
    tests/test_spectral.py tests/test_km.py tests/test_gradients.py \
    tests/test_fast_gradients.py tests/test_render.py tests/test_lockstep.py \
    tests/test_radiometry.py
  grep -E "^=+ .*(passed|failed|error)" "$OUT/tests.log" | tail -n 1 > "$OUT/tests.txt"
  grep -E "FAILED|ERROR" "$OUT/tests.log" | head -n 40 >> "$OUT/tests.txt"
  log "tests: $(grep -c PASSED "$OUT/tests.log") passed, $(grep -c -E ' FAILED| ERROR' \
    "$OUT/tests.log") failed or errors (tests.txt)"
fi
log "done; tables in $OUT/RESULTS.md"
