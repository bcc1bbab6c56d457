#!/usr/bin/env bash
# The GPU figures of docs/PERFORMANCE.md ("A GPU"), made in one call on a lent GPU machine, which
# has JAX with CUDA but no network and no atlasnn install: the package runs from src/.
#
#   bash scripts/gpu_check.sh            # results and a log in $OUT (default: gpu-out/)
#   SMALL=1 bash scripts/gpu_check.sh    # the same steps at toy sizes: a dry run on any machine
#
# The GPU machine lacks tomli-w: first, here, `pip download tomli-w --no-deps --only-binary=:all: -d .whl`
# (with .whl/ ignored by git) and carry .whl with the call; the script installs it.
#
# Steps, most important first, each under its own time limit so that a slow one cannot take the
# rest with it (on an H100 they took about 7 minutes; run it with a call limit of 600 s): (1) accuracy of 64 seeds trained on this device against DOP853, full float32 matrix
# products (atlasnn's default); (2) per-seed throughput for S = 1, 16, 256, 1 024 seeds in one
# program on oscillator-short and the Hénon–Heiles target; (3) the accuracy with JAX's own default
# products (TF32 on a recent GPU); (4) an end-to-end quick reproduction through the CLI; (5) the
# lone one-core CPU figure of the same machine, for a same-machine ratio; (6) the throughput with
# TF32 products where the matrix products are largest.
set -u
OUT=${OUT:-gpu-out}
mkdir -p "$OUT"
export PYTHONPATH="$PWD/src:$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1 MPLBACKEND=Agg
export ATLASNN_CACHE_DIR=${ATLASNN_CACHE_DIR:-/tmp/atlasnn-jax-cache}
PY=${PY:-python3}
if [ -d .whl ]; then  # pure-Python packages the machine lacks (tomli-w), carried as wheels
  $PY -m pip install -q --no-index --no-deps --no-compile --target /tmp/site .whl/*.whl && export PYTHONPATH="$PYTHONPATH:/tmp/site"
fi
if [ "${SMALL:-0}" = 1 ]; then
  SEEDS=4 EPOCHS=300 SIZES="1 4" BEPOCHS=50 ROUNDS=1 RSEEDS=2
else
  SEEDS=64 EPOCHS=20000 SIZES="1 16 256 1024" BEPOCHS=200 ROUNDS=2 RSEEDS=16
fi

step() {  # step LIMIT_S NAME COMMAND...: run with a limit, say how it ended and how long it took
  local limit=$1 name=$2 t=$SECONDS
  shift 2
  echo "== $name (limit ${limit} s)"
  timeout "$limit" "$@"
  echo "== $name: exit $? after $((SECONDS - t)) s"
}

{
  echo "== machine"
  nvidia-smi --query-gpu=name,memory.total,driver_version,clocks.sm,clocks.max.sm --format=csv 2>&1 || echo "no nvidia-smi"
  $PY -c "import jax, sys; print('python', sys.version.split()[0], 'jax', jax.__version__, jax.devices())"
  nproc
} 2>&1 | tee "$OUT/log.txt"

{
  step 150 "accuracy, full float32 products" $PY -m benchmarks.device_accuracy --seeds $SEEDS --epochs $EPOCHS \
    --out "$OUT/device_accuracy_gpu.json"
  # one step per configuration: on the H100 the two together took over 240 s with an empty cache
  step 150 "seed-batch throughput, oscillator-short" $PY -m benchmarks.seed_batch --configs osc-short \
    --sizes $SIZES --epochs $BEPOCHS --rounds $ROUNDS --one-core docs/benchmarks/seed_batch_one_core.json \
    --out "$OUT/seed_batch_gpu_osc.json"
  step 200 "seed-batch throughput, Hénon–Heiles target" $PY -m benchmarks.seed_batch --configs hh-target \
    --sizes $SIZES --epochs $BEPOCHS --rounds 1 --one-core docs/benchmarks/seed_batch_one_core.json \
    --out "$OUT/seed_batch_gpu_hh.json"
  ATLASNN_MATMUL_PRECISION=default step 90 "accuracy, JAX's default products" $PY -m benchmarks.device_accuracy \
    --seeds $SEEDS --epochs $EPOCHS --out "$OUT/device_accuracy_gpu_tf32.json"
  step 120 "quick reproduction through the CLI" $PY -c "import sys; from atlasnn.cli import main; sys.exit(main())" \
    reproduce oscillator-short --quick --seeds $RSEEDS --seed-batch $RSEEDS --figures none --no-progress \
    --out /tmp/gpu-reproduce --overwrite
  cp /tmp/gpu-reproduce/tables.md "$OUT/reproduce_tables.md" 2>/dev/null
  JAX_PLATFORMS=cpu step 90 "one core of this machine's CPU" taskset -c 0 $PY -m benchmarks.seed_batch \
    --configs osc-short hh-target --sizes 1 --epochs $BEPOCHS --rounds 3 --out "$OUT/seed_batch_host_one_core.json"
  ATLASNN_MATMUL_PRECISION=default step 90 "throughput with JAX's default products" $PY -m benchmarks.seed_batch \
    --configs hh-target --sizes ${SIZES##* } --epochs $BEPOCHS --rounds $ROUNDS --out "$OUT/seed_batch_gpu_tf32.json"
} 2>&1 | tee -a "$OUT/log.txt"
