set -u
python3 -m pip install -q --no-index --no-deps --no-compile --no-cache-dir --upgrade --target /tmp/site .whl/*.whl || exit 1
export PYTHONPATH=/tmp/site:$PWD PYTHONUNBUFFERED=1 XLA_PYTHON_CLIENT_PREALLOCATE=false JAX_LOG_COMPILES=1
learner() {  # seeds, log: Python stacks every 30 s, each compile logged with its time
  timeout 175 python3 -c "
import faulthandler, sys, runpy, time
faulthandler.dump_traceback_later(30, repeat=True)
sys.argv = ['bench/accelerator_learner.py', '--seeds', '$1', '--chunks', '5', '--csv', '$OUT/learner.csv']
runpy.run_path('bench/accelerator_learner.py', run_name='__main__')" > "$OUT/learner-$1.log" 2>&1
}
learner 1 &
learner 256 &
for spec in "hopper 60 1024 8192" "ant 50 4096" "humanoid 60 4096"; do
  set -- $spec
  echo "== $1 at ${SECONDS}s" >> "$OUT/physics.err"
  timeout "$2" python3 bench/accelerator.py --task "$1" --batch "${@:3}" --steps 1000 --csv "$OUT/physics.csv" 2>> "$OUT/physics.err"
done
wait
for t in hopper ant humanoid; do timeout 20 python3 bench/accelerator.py --task $t --mujoco-c --steps 20000 --csv "$OUT/physics.csv" 2>> "$OUT/physics.err"; done
echo "done at ${SECONDS}s"
cat "$OUT"/*.csv
