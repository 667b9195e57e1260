#!/usr/bin/env bash
# The prepared accelerator check (issues 36, 56): one call of at most BUDGET seconds (500: done
# inside 9 minutes whatever happens, each measurement in its own process and time limit).
#   1. the table that matters (bench/accelerator_learner.py, $OUT/accelerator-learner.csv): the
#      device learner (AdaRL, Hopper, nominal physics) at 1 to 1,024 seeds with the capped solver
#      (100,4) and the XML's: seed-steps/s, one chunk's time over its updates, the memory, the
#      most telling entries first (LEARNER_RUNS, task:dynamics:seeds:solver);
#   2. the host backend's rate (one seed, the machine's CPU), the reference;
#   3. raw physics per PHYSICS entry (bench/accelerator.py): MuJoCo C on one thread, and MJX
#      env-steps/s of a vmapped batch with the XML's solver and with each of SOLVERS.
# Every measurement's row is appended to its CSV as soon as it ends; one that fails or hits its
# limit gets a row saying so (with its last progress line), and one the budget has no time left
# for gets a `skipped` row, so the CSVs always say what was and was not measured.
# Run from the repository root. Where adarl's dependencies are missing (the device machine has
# Python 3.12 and its own JAX but no MuJoCo), put their wheels in .whl/ first (docs/benchmarks.md,
# "Accelerator groundwork": bench/accelerator_wheels.sh) and carry it.
# Env: OUT (results folder, default .), WHEELS, PYTHON, LEARNER_RUNS, CHUNKS, BUFFER, HOST (1: the
# host line), PHYSICS (task:batch,batch,... entries; empty: none), SOLVERS (--device-solver
# values beside the XML's), STEPS, PLATFORM (default gpu), LIMIT (most seconds per measurement),
# BUDGET (seconds for the whole call, from its start). Each measurement's stderr goes to
# $OUT/accelerator.err. Sized from the H200 run of 2026-12-04 (docs/benchmarks.md): a device
# measurement compiled for ~45-60 s and a Hopper chunk took 2-6 s, so about 75 s each: the first
# six entries fit one call; the rest in a second call, e.g.
#   LEARNER_RUNS="hopper:nominal:64:100,4 hopper:nominal:16:100,4 hopper:nominal:256:xml \
#   hopper:nominal:64:xml hopper:nominal:16:xml walker2d:paper:1024:100,4" HOST=0 PHYSICS=""
set -u
case "${1:-}" in  # settings come from the environment (above); no arguments
  "") ;;
  -h|--help) sed -n '2,/^set /p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
  *) echo "$(basename "$0"): error: unknown argument '$1'; allowed: -h, --help (settings are environment variables)" >&2; exit 2 ;;
esac
OUT=${OUT:-.}
LEARNER_RUNS=${LEARNER_RUNS-"hopper:nominal:1024:100,4 hopper:nominal:1024:xml \
hopper:nominal:1:100,4 hopper:nominal:1:xml hopper:nominal:256:100,4 hopper:nominal:256:xml \
hopper:nominal:64:100,4 hopper:nominal:16:100,4 hopper:nominal:64:xml hopper:nominal:16:xml"}
CHUNKS=${CHUNKS:-5}
BUFFER=${BUFFER:-100000}
HOST=${HOST:-1}
PHYSICS=${PHYSICS-"hopper:1024"}
SOLVERS=${SOLVERS-"100,4 1,4"}
STEPS=${STEPS:-200}
PLATFORM=${PLATFORM:-gpu}
LIMIT=${LIMIT:-150}
BUDGET=${BUDGET:-500}
MIN_LIMIT=20  # a measurement with less time left than this is skipped
mkdir -p "$OUT"
CSV="$OUT/accelerator.csv"
LEARN="$OUT/accelerator-learner.csv"
ERR="$OUT/accelerator.err"
rm -f "$CSV" "$LEARN" "$ERR"
LEARN_HEADER="task,dynamics,solver,backend,platform,seeds,chunk_steps,compile_s,chunk_s,seed_steps_per_s,update_ms,memory_mb"
PHYSICS_HEADER="task,kind,platform,batch,steps,compile_s,run_s,env_steps_per_s"
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
timeout 60 $PY -c "import sys, jax, mujoco, numpy; from mujoco import mjx; \
print('python', sys.version.split()[0], 'jax', jax.__version__, 'mujoco', mujoco.__version__, \
'numpy', numpy.__version__); print('devices', jax.devices())" 2>&1 | grep -v -i warn
grep -E '^jax(lib)?==' constraints.txt 2>/dev/null | tr '\n' ' ' | sed 's/^/the project pins: /; s/$/\n/'
nvidia-smi -L 2>/dev/null || echo "nvidia-smi: none"
N=0
row() {  # CSV HEADER ROW: append ROW to CSV (its header first) and print it
  [ -s "$1" ] || echo "$2" > "$1"
  echo "$3" >> "$1"
  echo "$3"
}
run() {  # CSV HEADER BEFORE AFTER ARGS...: one measurement under min(LIMIT, the budget left);
  # a row "BEFORE,<why>,AFTER,<note>" where it fails, times out or is skipped
  local csv=$1 header=$2 before=$3 after=$4
  shift 4
  N=$((N + 1))
  local left=$((BUDGET - SECONDS))
  local limit=$((left < LIMIT ? left : LIMIT))
  if [ "$limit" -lt "$MIN_LIMIT" ]; then
    row "$csv" "$header" "$before,skipped,$after,budget of ${BUDGET}s spent at ${SECONDS}s"
    return
  fi
  echo "== $N at ${SECONDS}s, limit ${limit}s: $*" >> "$ERR"
  timeout "$limit" $PY "$@" --csv "$csv" 2> "$ERR.last"
  local rc=$?
  cat "$ERR.last" >> "$ERR"
  if [ $rc -ne 0 ]; then
    local last why=failed
    last=$(grep -v -i warn "$ERR.last" | grep -v '^\s*$' | tail -1 | tr ',' ';' | cut -c1-160)
    [ $rc -eq 124 ] && why=timeout
    row "$csv" "$header" "$before,$why,$after,rc=$rc after ${limit}s limit: $last"
  fi
  rm -f "$ERR.last"
}
echo "$LEARN_HEADER"
for entry in $LEARNER_RUNS; do
  IFS=: read -r task dynamics seeds solver <<< "$entry"
  run "$LEARN" "$LEARN_HEADER" "$task,$dynamics,${solver//,//},device" "$seeds" \
    bench/accelerator_learner.py --task "$task" --dynamics "$dynamics" --seeds "$seeds" \
    --device-solver "$solver" --chunks "$CHUNKS" --buffer-size "$BUFFER"
done
if [ "$HOST" = 1 ]; then
  JAX_PLATFORMS=cpu run "$LEARN" "$LEARN_HEADER" "hopper,nominal,,host" 1 \
    bench/accelerator_learner.py --host --seeds 1 --chunks "$CHUNKS" --buffer-size "$BUFFER"
fi
[ -n "$PHYSICS" ] && echo "$PHYSICS_HEADER"
for entry in $PHYSICS; do
  task=${entry%%:*}
  batches=${entry#*:}
  run "$CSV" "$PHYSICS_HEADER" "$task,mujoco_c" 1 \
    bench/accelerator.py --task "$task" --mujoco-c --steps $((STEPS * 20))
  run "$CSV" "$PHYSICS_HEADER" "$task,mjx" "$batches" \
    bench/accelerator.py --task "$task" --platform "$PLATFORM" --batch ${batches//,/ } \
    --steps "$STEPS"
  for solver in $SOLVERS; do
    run "$CSV" "$PHYSICS_HEADER" "$task,mjx-${solver//,//}" "$batches" \
      bench/accelerator.py --task "$task" --platform "$PLATFORM" --batch ${batches//,/ } \
      --steps "$STEPS" --device-solver "$solver"
  done
done
echo "written in ${SECONDS}s (budget ${BUDGET}s): $LEARN ${PHYSICS:+$CSV}"
