#!/usr/bin/env bash
# The prepared accelerator check of issue 36 (≤ 8 minutes on the device machine, one table):
#   1. the host backend's training rate (AdaRL, Hopper, one seed; bench/accelerator_learner.py --host)
#   2. the device backend's training rate at 1, 16, 64, 256, 1,024 seeds: seed-steps/s, one
#      chunk's time over its updates, the memory used (bench/accelerator_learner.py)
#   3. raw physics: MuJoCo C one thread, and MJX env-steps/s of a vmapped batch (bench/accelerator.py)
# Run from the repository root. Where adarl's dependencies are missing (the device machine has
# Python 3.12 and JAX but no MuJoCo), put their wheels in .whl/ first (docs/benchmarks.md,
# "Accelerator groundwork": the list and the pip download command) and carry it.
# Env: OUT (results folder, default .), WHEELS, PYTHON, LEARNER_SEEDS, CHUNKS, BUFFER, ENV_BATCHES, STEPS,
# PLATFORM (default gpu), LIMIT (seconds per measurement).
set -u
OUT=${OUT:-.}
LEARNER_SEEDS=${LEARNER_SEEDS:-"1 16 64 256 1024"}
CHUNKS=${CHUNKS:-20}
BUFFER=${BUFFER:-100000}
ENV_BATCHES=${ENV_BATCHES:-"1 1024 8192"}
STEPS=${STEPS:-1000}
PLATFORM=${PLATFORM:-gpu}
LIMIT=${LIMIT:-100}
mkdir -p "$OUT"
CSV="$OUT/accelerator.csv"
LEARN="$OUT/accelerator-learner.csv"
rm -f "$CSV" "$LEARN"
WHEELS=${WHEELS:-.whl}  # WHEELS=none: use the Python at hand as it is
if ls "$WHEELS"/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site "$WHEELS"/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=${PYTHONPATH:-}:$PWD
fi
PY=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
$PY -c "import sys, jax, mujoco, numpy; from mujoco import mjx; \
print('python', sys.version.split()[0], 'jax', jax.__version__, 'mujoco', mujoco.__version__, \
'numpy', numpy.__version__); print('devices', jax.devices())" 2>&1 | grep -v -i warn
nvidia-smi -L 2>/dev/null || echo "nvidia-smi: none"
N=0
run() {  # one measurement, its own time limit: a failure or timeout loses only itself
  N=$((N + 1))
  timeout "$LIMIT" $PY "$@" 2> "$OUT/accelerator-$N.err"
  rc=$?
  [ $rc -eq 0 ] || { echo "failed,$*,rc=$rc"; grep -v -i warn "$OUT/accelerator-$N.err" | tail -3; }
}
echo "backend,platform,seeds,chunk_steps,compile_s,chunk_s,seed_steps_per_s,update_ms,memory_mb"
JAX_PLATFORMS=cpu run bench/accelerator_learner.py --host --seeds 1 --chunks "$CHUNKS" \
  --buffer-size "$BUFFER" --csv "$LEARN"
for n in $LEARNER_SEEDS; do
  run bench/accelerator_learner.py --seeds "$n" --chunks "$CHUNKS" --buffer-size "$BUFFER" --csv "$LEARN"
done
if [ -n "$ENV_BATCHES" ]; then
  echo "kind,platform,batch,steps,compile_s,run_s,env_steps_per_s"
  run bench/accelerator.py --mujoco-c --steps $((STEPS * 20)) --csv "$CSV"
  for b in $ENV_BATCHES; do
    run bench/accelerator.py --platform "$PLATFORM" --batch "$b" --steps "$STEPS" --csv "$CSV"
  done
fi
echo "written: $LEARN ${ENV_BATCHES:+$CSV}"
