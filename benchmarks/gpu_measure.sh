#!/usr/bin/env bash
# The device measurements of results/perf/gpu.md, as run on a lent GPU machine (an image with
# CuPy, numpy, scipy, pandas and matplotlib but not this project): ducc0 comes as a wheel in
# .whl/, the package is put on the path without installing it, and every output goes to
# OUT (default results/perf/gpu).  Each step has its own time limit, the most telling first;
# the limits add up to 630 s: all of them do not fit one device call of under 8 minutes,
# so a call picks its STEPS.  COMMIT names the code's
# commit in the rows that carry one (a copy of the tree may have no .git).
#   OUT/device.txt               the GPU, the CPU, the packages
#   OUT/pytest-gpu.txt           the CuPy tests (operator and device-resident solves)
#   OUT/cost-law.csv             bench_cost_law.py: the paper-sweep cold top step, one row per
#                                solve: --operator gpu at 2048^2-16384^2, the CPU at 4096^2 on
#                                every core and at 2048^2 on 2, 4, 8 and 16 threads
#   OUT/surface-population.csv   the four surface families at 4096^2, --operator gpu
#   OUT/device-partial.csv       bench_device_partial.py: partial products against matvecs at 4096^2
#   OUT/steps.log                every step's output, with profile_solve.py's profiles of a 4096^2 solve
#                                (profile-blocking: each kernel launch waited for, CUDA_LAUNCH_BLOCKING=1,
#                                so the device time lands on the call that launched it)
# STEPS picks steps by label (pytest-gpu gpu-sizes profile-gpu profile-blocking device-partial gpu-16384
# gpu-families cpu-all-cores cpu-threads); GPU_SIZES, BIG_SIZES, FAMILY_SIZE, PROFILE_SIZE, CPU_SIZE, SCALING_SIZE and
# SCALING_THREADS change sizes and threads, PROFILE_CHAINS the functions whose callers the profile
# traces (a regex; default CuPy's asarray: what moves host arrays to the device), PYTEST_K selects tests (pytest -k; default the CuPy cases: the
# NumPy ones run everywhere) and PYTEST_S is their limit (a cold kernel cache took 39 s for the CuPy cases).
set -o pipefail
export PYTHONUNBUFFERED=1
OUT=${OUT:-results/perf/gpu}
ROOT=$(pwd)
COMMIT=${COMMIT:-unknown}
mkdir -p "$OUT"
OUT=$(cd "$OUT" && pwd)
WHEELS=${WHEELS:-.whl}
if ls "$WHEELS"/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site "$WHEELS"/*.whl || exit 3
fi
if ! python3 -c "import contactbench.problems" 2>/dev/null; then
  mkdir -p /tmp/cbroot/contactbench
  for d in harness problems solvers; do ln -sfn "$ROOT/$d" "/tmp/cbroot/contactbench/$d"; done
  cp contactbench/*.py /tmp/cbroot/contactbench/
  export PYTHONPATH=/tmp/cbroot:/tmp/site${PYTHONPATH:+:$PYTHONPATH}
fi
GPU=$(nvidia-smi --query-gpu=name --format=csv,noheader 2>/dev/null | head -1)
CPU=$(lscpu 2>/dev/null | sed -n 's/^Model name: *//p' | head -1)
export CONTACTBENCH_HOST=${CONTACTBENCH_HOST:-"${GPU:-no GPU} + ${CPU:-CPU} x$(nproc)"}
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv; echo "cores: $(nproc)"; echo "cpu: $CPU"
  echo "commit: $COMMIT"; date -u +"date: %Y-%m-%dT%H:%M:%SZ"
  python3 -c "import sys, cupy, numpy, scipy, ducc0; print('python', sys.version.split()[0], 'cupy', cupy.__version__, 'numpy', numpy.__version__, 'scipy', scipy.__version__, 'ducc0', ducc0.__version__)"
} > "$OUT/device.txt" 2>&1
STEPS=${STEPS:-all}  # the steps to run, by label (e.g. "pytest-gpu gpu-sizes"), or all
step() {  # step LIMIT_S LABEL COMMAND...: one time-limited step, its output kept in OUT/steps.log
  local limit=$1 label=$2; shift 2
  [[ $STEPS == all || " $STEPS " == *" ${label%%:*} "* ]] || return 0  # "cpu-threads:4" is step cpu-threads
  echo "== $label ($(date -u +%H:%M:%S), limit ${limit} s)"
  timeout "$limit" "$@"; echo "== $label: exit $?"
}
{
  step ${PYTEST_S:-75} pytest-gpu bash -c "cd /tmp && PYTHONPATH='${PYTHONPATH:+$PYTHONPATH:}$ROOT' python3 -m pytest -q -p no:cacheprovider \
    -o addopts= --import-mode=importlib -rs -k '${PYTEST_K:-cupy or cuda}' '$ROOT/tests/problems/test_operators_gpu.py' \
    '$ROOT/tests/solvers/test_device_resident.py' 2>&1 | tail -6 > '$OUT/pytest-gpu.txt'; cat '$OUT/pytest-gpu.txt'"
  step 100 gpu-sizes python3 benchmarks/bench_cost_law.py --operator gpu --sizes ${GPU_SIZES:-2048 4096 8192} \
    --solvers fast-dual-pccg --timeout 60 --out "$OUT"
  step 30 profile-gpu python3 benchmarks/profile_solve.py --size ${PROFILE_SIZE:-4096} --operator gpu --top 30 --callers 8 \
    --chains "${PROFILE_CHAINS:-from_data.py:.*asarray}" --depth 6
  step 40 profile-blocking env CUDA_LAUNCH_BLOCKING=1 python3 benchmarks/profile_solve.py --size ${PROFILE_SIZE:-4096} \
    --operator gpu --top 40
  step 40 device-partial python3 benchmarks/bench_device_partial.py --size ${PROFILE_SIZE:-4096} --out "$OUT/device-partial.csv"
  step 140 gpu-16384 python3 benchmarks/bench_cost_law.py --operator gpu --sizes ${BIG_SIZES:-16384} \
    --solvers fast-dual-pccg --timeout 90 --out "$OUT"
  step 65 gpu-families python3 benchmarks/bench_surface_population.py --operator gpu --sizes ${FAMILY_SIZE:-4096} \
    --seeds ${FAMILY_SIZE:-4096}:1 --variants default --timeout 30 --commit "$COMMIT" --out "$OUT"
  step 60 cpu-all-cores python3 benchmarks/bench_cost_law.py --operator fft --threads "$(nproc)" --sizes ${CPU_SIZE:-4096} \
    --solvers fast-dual-pccg --timeout 60 --out "$OUT"
  for t in ${SCALING_THREADS:-2 4 8 16}; do
    step 20 "cpu-threads:$t" python3 benchmarks/bench_cost_law.py --operator fft --threads "$t" --sizes ${SCALING_SIZE:-2048} \
      --solvers fast-dual-pccg --timeout 15 --out "$OUT"
  done
} 2>&1 | tee "$OUT/steps.log"
