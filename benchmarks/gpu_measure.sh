#!/usr/bin/env bash
# The GPU measurements of results/perf/gpu.md, as run on a lent GPU machine (an image with
# CuPy, numpy, scipy, pandas and matplotlib but not this project): ducc0 comes as a wheel in
# .whl/, the package is put on the path without installing it, and every output goes to
# OUT (default results/perf/gpu).  Each step has its own time limit, the cheap ones first; the
# limits add up to 470 s, one device call of under 8 minutes.  The solves' rows go to
# OUT/cost-law.csv (bench_cost_law.py: one row per solve, the host's name in "host").
set -o pipefail
export PYTHONUNBUFFERED=1
OUT=${OUT:-results/perf/gpu}
ROOT=$(pwd)
mkdir -p "$OUT"
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
{ nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv; echo "cores: $(nproc)"; lscpu | grep 'Model name'
  python3 -c "import cupy, numpy, scipy, ducc0; print('cupy', cupy.__version__, 'numpy', numpy.__version__, 'scipy', scipy.__version__, 'ducc0', ducc0.__version__)"
} > "$OUT/device.txt" 2>&1
(cd /tmp && PYTHONPATH="${PYTHONPATH:+$PYTHONPATH:}$ROOT" timeout 70 python3 -m pytest -q -p no:cacheprovider -o addopts= --import-mode=importlib -rs "$ROOT/tests/problems/test_operators_gpu.py" "$ROOT/tests/solvers/test_device_resident.py" 2>&1 | tail -4) > "$OUT/pytest-gpu.txt"
timeout "${MATVEC_S:-80}" python3 benchmarks/bench_gpu.py --sizes ${SIZES:-2048 4096 8192} --cpu-max 4096 --repeats 5 --out "$OUT/gpu-matvec.csv" 2>&1 | tee "$OUT/gpu-matvec.log"
{
  timeout "${COST_S:-100}" python3 benchmarks/bench_cost_law.py --operator gpu --sizes ${COST_SIZES:-2048 4096} --solvers fast-dual-pccg --timeout 90 --out "$OUT"
  timeout "${COST_S:-100}" python3 benchmarks/bench_cost_law.py --operator fft --threads "$(nproc)" --sizes ${COST_SIZES:-2048 4096} --solvers fast-dual-pccg --timeout 90 --out "$OUT"
  timeout "${BIG_S:-120}" python3 benchmarks/bench_cost_law.py --operator gpu --sizes ${BIG_SIZES:-8192} --solvers fast-dual-pccg --timeout 110 --out "$OUT"
} 2>&1 | tee "$OUT/cost.log"
