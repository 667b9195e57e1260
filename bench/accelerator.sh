#!/usr/bin/env bash
# Device Hopper throughput on the accelerator machine (issue 36, groundwork): MJX env-steps/s for
# a vmapped batch on the GPU and the CPU, and MuJoCo C single-thread as the reference.
# Run from the repository root with the wheels (and hopper.xml) in .whl/ (docs/benchmarks.md,
# "Accelerator groundwork"). Env: OUT (results folder, default .), STEPS (default 1000),
# GPU_BATCHES, CPU_BATCHES, PLATFORM (default gpu), LIMIT (seconds per measurement).
set -u
OUT=${OUT:-.}
STEPS=${STEPS:-1000}
GPU_BATCHES=${GPU_BATCHES:-"1 64 1024 8192"}
CPU_BATCHES=${CPU_BATCHES:-"1 64"}
CPU_STEPS=${CPU_STEPS:-200}
PLATFORM=${PLATFORM:-gpu}
LIMIT=${LIMIT:-100}
mkdir -p "$OUT"
CSV="$OUT/accelerator.csv"
rm -f "$CSV"
if ls .whl/*.whl >/dev/null 2>&1; then
  python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade \
    --target /tmp/site .whl/*.whl || exit 1
  export PYTHONPATH=/tmp/site:$PWD
else
  export PYTHONPATH=${PYTHONPATH:-}:$PWD
fi
XML=""
[ -f .whl/hopper.xml ] && XML="--xml .whl/hopper.xml"
export PYTHONUNBUFFERED=1
python3 -c "import sys, jax, mujoco, numpy; from mujoco import mjx; \
print('python', sys.version.split()[0], 'jax', jax.__version__, 'mujoco', mujoco.__version__, \
'numpy', numpy.__version__); print('devices', jax.devices())" 2>&1 | grep -v Warning
nvidia-smi -L 2>/dev/null || echo "nvidia-smi: none"
echo "kind,platform,batch,steps,compile_s,run_s,env_steps_per_s"
N=0
run() {  # one measurement, its own time limit: a failure or timeout loses only itself
  N=$((N + 1))
  timeout "$LIMIT" python3 bench/accelerator.py $XML --csv "$CSV" "$@" 2> "$OUT/accelerator-$N.err"
  rc=$?
  [ $rc -eq 0 ] || { echo "failed,$*,rc=$rc"; grep -v Warning "$OUT/accelerator-$N.err" | tail -3; }
}
run --mujoco-c --steps $((STEPS * 20))
for b in $GPU_BATCHES; do run --platform "$PLATFORM" --batch "$b" --steps "$STEPS"; done
for b in $CPU_BATCHES; do run --platform cpu --batch "$b" --steps "$CPU_STEPS"; done
echo "written: $CSV"
