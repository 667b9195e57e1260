#!/usr/bin/env bash
# The prepared accelerator check of issue 36 (about 8 minutes on the device machine, two tables):
#   1. training (bench/accelerator_learner.py): the host backend's rate (AdaRL, Hopper, one seed,
#      on the machine's CPU), then the device backend's for each LEARNER_RUNS entry
#      (task:dynamics:seeds:solver): seed-steps/s, one chunk's time over its updates, the memory
#   2. raw physics per PHYSICS entry (bench/accelerator.py): MuJoCo C on one thread, and MJX
#      env-steps/s of a vmapped batch with the XML's solver and with each of SOLVERS
# Run from the repository root. Where adarl's dependencies are missing (the device machine has
# Python 3.12 and JAX but no MuJoCo), put their wheels in .whl/ first (docs/benchmarks.md,
# "Accelerator groundwork": the list and the pip download command) and carry it.
# Env: OUT (results folder, default .), WHEELS, PYTHON, LEARNER_RUNS, CHUNKS, BUFFER,
# PHYSICS (task:batch,batch,... entries; empty: no raw physics), SOLVERS (--device-solver values
# beside the XML's), STEPS, PLATFORM (default gpu), LIMIT (seconds per measurement).
# Each measurement's stderr goes to $OUT/accelerator.err. Sized from the H200 run of 2026-12-04
# (docs/benchmarks.md): a device measurement compiled for ~45-60 s and a Hopper chunk took
# 4-6 s there with the XML's solver, so 5 timed chunks and 150 s each, the most telling first,
# about 8 minutes in all; other seed counts in a second call, e.g.
#   LEARNER_RUNS="hopper:nominal:16:100,4 hopper:nominal:64:100,4 hopper:nominal:256:100,4" PHYSICS=""
set -u
case "${1:-}" in  # settings come from the environment (above); no arguments
  "") ;;
  -h|--help) sed -n '2,/^set /p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
  *) echo "$(basename "$0"): error: unknown argument '$1'; allowed: -h, --help (settings are environment variables)" >&2; exit 2 ;;
esac
OUT=${OUT:-.}
LEARNER_RUNS=${LEARNER_RUNS-"hopper:nominal:1024:100,4 hopper:nominal:1024:xml \
hopper:nominal:1:100,4 walker2d:paper:1024:100,4"}
CHUNKS=${CHUNKS:-5}
BUFFER=${BUFFER:-100000}
PHYSICS=${PHYSICS-"hopper:1024"}
SOLVERS=${SOLVERS-"100,4 1,4"}
STEPS=${STEPS:-200}
PLATFORM=${PLATFORM:-gpu}
LIMIT=${LIMIT:-150}
mkdir -p "$OUT"
CSV="$OUT/accelerator.csv"
LEARN="$OUT/accelerator-learner.csv"
ERR="$OUT/accelerator.err"
rm -f "$CSV" "$LEARN" "$ERR"
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
  echo "== $N at ${SECONDS}s: $*" >> "$ERR"
  timeout "$LIMIT" $PY "$@" 2> "$ERR.last"
  rc=$?
  cat "$ERR.last" >> "$ERR"
  [ $rc -eq 0 ] || { echo "failed,$*,rc=$rc"; grep -v -i warn "$ERR.last" | tail -3; }
  rm -f "$ERR.last"
}
echo "task,dynamics,solver,backend,platform,seeds,chunk_steps,compile_s,chunk_s,seed_steps_per_s,update_ms,memory_mb"
JAX_PLATFORMS=cpu run bench/accelerator_learner.py --host --seeds 1 --chunks "$CHUNKS" \
  --buffer-size "$BUFFER" --csv "$LEARN"
for entry in $LEARNER_RUNS; do
  IFS=: read -r task dynamics seeds solver <<< "$entry"
  run bench/accelerator_learner.py --task "$task" --dynamics "$dynamics" --seeds "$seeds" \
    --device-solver "$solver" --chunks "$CHUNKS" --buffer-size "$BUFFER" --csv "$LEARN"
done
if [ -n "$PHYSICS" ]; then
  echo "task,kind,platform,batch,steps,compile_s,run_s,env_steps_per_s"
  for entry in $PHYSICS; do
    task=${entry%%:*}
    batches=${entry#*:}
    run bench/accelerator.py --task "$task" --mujoco-c --steps $((STEPS * 20)) --csv "$CSV"
    run bench/accelerator.py --task "$task" --platform "$PLATFORM" --batch ${batches//,/ } \
      --steps "$STEPS" --csv "$CSV"
    for solver in $SOLVERS; do
      run bench/accelerator.py --task "$task" --platform "$PLATFORM" --batch ${batches//,/ } \
        --steps "$STEPS" --csv "$CSV" --device-solver "$solver"
    done
  done
fi
echo "written in ${SECONDS}s: $LEARN ${PHYSICS:+$CSV}"
