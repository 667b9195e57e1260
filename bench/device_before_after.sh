#!/usr/bin/env bash
# The device learner's seed-steps per second on this machine's CPU, an older checkout against
# this one, in one run, alternating (before, after, before, after) so that a drift of the
# machine falls on both sides. Each measurement is bench/accelerator_learner.py of its own
# checkout (its chunks pipelined as that code trains), 16 seeds, Hopper, nominal physics, the
# solver given explicitly (its default changed in issue 56). Take it on an idle machine.
#
#   git worktree add --detach /tmp/before cd9fa17   # the commit before issue 56's device changes
#   bash bench/device_before_after.sh /tmp/before OUT.csv
#
# OUT.csv: accelerator_learner.py's columns with `code` (before/after) and `round` in front.
set -euo pipefail
if [ "${1:-}" = -h ] || [ "${1:-}" = --help ]; then
  sed -n '2,11p' "$0" | sed 's/^# \{0,1\}//'
  exit 0
fi
if [ $# -ne 2 ] || [ ! -d "$1" ]; then
  echo "usage: device_before_after.sh BEFORE_CHECKOUT OUT.csv (got: ${*:-nothing}; BEFORE_CHECKOUT must be a folder)" >&2
  exit 2
fi
before=$(cd "$1" && pwd)
out=$2
after=$(cd "$(dirname "$0")/.." && pwd)
flags=(--seeds 16 --chunks 5 --buffer-size 10000 --device-solver 100,4)
: > "$out.tmp"
for round in 1 2; do
  for side in before after; do
    tree=$before
    [ "$side" = after ] && tree=$after
    line=$(cd "$tree" && JAX_PLATFORMS=cpu PYTHONPATH="$tree" python bench/accelerator_learner.py \
      "${flags[@]}" | grep -E '^([^,]*,){11}[^,]*$' | grep -v '^task,')  # the row, not MJX's notes
    echo "$side,$round,$line" | tee -a "$out.tmp"
  done
done
{ echo "code,round,task,dynamics,solver,backend,platform,seeds,chunk_steps,compile_s,chunk_s,seed_steps_per_s,update_ms,memory_mb"; cat "$out.tmp"; } > "$out"
rm "$out.tmp"
