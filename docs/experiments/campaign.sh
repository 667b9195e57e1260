#!/usr/bin/env bash
# The campaign's units, one sweep after another on both cores (order: below). Each sweep
# resumes every unit from its newest checkpoint and skips finished ones, so running this again
# (at the start of every session) continues where the last session stopped:
#   git worktree add --detach /work/camp COMMIT     # the campaign's frozen code (campaign.md)
#   git worktree add --detach /work/camp3 COMMIT3   # claim 1 across tasks' frozen code
#   ../shared/tools/background /work/main/results/campaign.log bash /work/main/docs/experiments/campaign.sh > /work/main/results/campaign.pid
# and, before a session ends, stop it without losing a step (each unit writes a checkpoint
# where it stops, and the sweep exits 130, which ends this script too):
#   kill -TERM -- -$(cat /work/main/results/campaign.pid)
# (CAMPAIGN_CODE, CAMPAIGN_CODE3, CAMPAIGN_PYTHON and CAMPAIGN_RESULTS replace the paths below in
# its test.)
# Bash reads a script as it runs it: replace this file (write a copy, then mv), never edit it in
# place while the campaign runs.
set -u
E=$(cd "$(dirname "$0")" && pwd)
CODE=${CAMPAIGN_CODE:-/work/camp}  # python -m puts the working folder first: the frozen code runs
PY=${CAMPAIGN_PYTHON:-/work/main/.venv/bin/python}
R=${CAMPAIGN_RESULTS:-/work/main/results}
mkdir -p "$R"
# From 2026-12-05 the sweeps of more than a session's units run one seed per unit (campaign.md,
# "One seed per unit"): the sweep files beside this script; RNAC, whose seeds share a vmapped
# update, in the preset's units of five. From 18:05 Table 1's primary pair first (campaign.md,
# "The primary pair first"): Humanoid SAC, then Ant's AdaRL and SAC, then the other methods;
# from 2026-12-05 20:38 RNAC before the rest of Humanoid's Parseval units, so that every method
# of Table 1 has a row first (campaign.md, "RNAC before Parseval's rest").
# An entry FILE|FOLDER runs FILE into results/FOLDER, a sweep folder it shares with FOLDER's file.
# Table 1 finished on 2026-12-05, claim 2 across tasks on 2026-12-07 (every row committed). From
# 2026-12-07 (session 29): claim 1 across tasks first (campaign.md, "Session 29"): its primary pair
# in 15 blocks of one seed (20 units of minutes each), every block followed by its robustness grids
# and its export to the committed rows, so that a finished block survives a new machine; then
# Walker2d's 3M-step units, which outlast a session, and fixed-rank-power.
CODE3=${CAMPAIGN_CODE3:-/work/camp3}  # claim 1 across tasks' frozen code (its pre-registration)
C1=$E/claim1-across-tasks
R1=$R/claim1-across-tasks
cd "$CODE3" || exit 2
$PY "$E/claim1_across_tasks.py" restore "$R1" || exit 2  # the committed blocks (a new machine)
for seed in $(seq 0 14); do
  echo "== $(date -u +%FT%TZ) claim 1 across tasks, block $seed"
  $PY -m adarl.cli.main sweep "$C1/primary-seed-$seed.yaml" --out "$R1" --workers 2 --no-progress
  code=$?
  echo "== $(date -u +%FT%TZ) block $seed exited $code"
  if [ "$code" -eq 130 ] || [ "$code" -eq 2 ]; then exit "$code"; fi
  $PY "$E/claim1_across_tasks.py" evaluate "$R1" --code "$CODE3"
  code=$?
  echo "== $(date -u +%FT%TZ) grids exited $code"
  if [ "$code" -eq 130 ] || [ "$code" -eq 143 ]; then exit "$code"; fi
  $PY "$E/claim1_across_tasks.py" export "$R1"
done
# claim 2 in the paper's hedged form (issue 65 §2, claim2-hedged.md): 81 units of minutes on the
# same frozen code, its committed rows restored first, exported when the sweep ends
R2=$R/claim2-hedged
$PY "$E/claim1_across_tasks.py" restore "$R2" --rows "$E/claim2-hedged/rows" || exit 2
echo "== $(date -u +%FT%TZ) claim 2 hedged"
$PY -m adarl.cli.main sweep "$E/claim2-hedged/claim2-hedged.yaml" --out "$R2" --workers 2 --no-progress
code=$?
echo "== $(date -u +%FT%TZ) claim 2 hedged exited $code"
if [ "$code" -eq 130 ] || [ "$code" -eq 2 ]; then exit "$code"; fi
$PY "$E/claim2_hedged.py" export "$R2"
W=$E/paper-schedule-walker2d
for entry in "$W/paper-schedule-walker2d-seeds-2-4.yaml|paper-schedule-walker2d" \
  "$W/paper-schedule-walker2d-sac-0-1.yaml|paper-schedule-walker2d" \
  "$W/paper-schedule-walker2d.yaml" fixed-rank-power; do
  sweep=${entry%%|*}
  name=$(basename "$sweep" .yaml)
  [[ $entry == *"|"* ]] && name=${entry#*|}
  echo "== $(date -u +%FT%TZ) $sweep"
  cd "$CODE" || exit 2
  $PY -m adarl.cli.main sweep "$sweep" --out "$R/$name" --workers 2 --no-progress
  code=$?
  echo "== $(date -u +%FT%TZ) $(basename "$sweep" .yaml) exited $code"
  # stopped (Ctrl-C, SIGTERM: 130) or refused (bad input: 2): go no further
  if [ "$code" -eq 130 ] || [ "$code" -eq 2 ]; then exit "$code"; fi
  # issue 34 §3.4 on Walker2d's 3M policies (paper-schedule-walker2d.md, "Robustness at 3M"),
  # once every unit is done, before a new machine can lose them: each AdaRL and SAC run that
  # has no suites/paper.csv yet (a stopped evaluation starts again at the next resume).
  if [ "$name" = paper-schedule-walker2d ] && [ "$code" -eq 0 ]; then
    todo=()
    for run in "$R/$name"/walker2d/{adarl_rank_rule-cumulative,sac}/seeds-*; do
      [ -d "$run" ] && [ ! -f "$run/suites/paper.csv" ] && todo+=("$run")
    done
    if [ "${#todo[@]}" -gt 0 ]; then
      echo "== $(date -u +%FT%TZ) robustness at 3M (paper suite, 5 episodes a point): ${#todo[@]} runs"
      $PY -m adarl.cli.main evaluate "${todo[@]}" --suite paper --episodes 5 --workers 2 --no-progress
      code=$?
      echo "== $(date -u +%FT%TZ) robustness exited $code"
      if [ "$code" -eq 130 ] || [ "$code" -eq 143 ]; then exit "$code"; fi  # stopped
    fi
  fi
done
