#!/usr/bin/env bash
# The campaign's units in the order of issue 34 §3, one after another on both cores. Each sweep
# resumes every unit from its newest checkpoint and skips finished ones, so running this again
# (at the start of every session) continues where the last session stopped:
#   git worktree add --detach /work/camp COMMIT     # the campaign's frozen code (campaign.md)
#   ../shared/tools/background /work/main/results/campaign.log bash /work/main/docs/experiments/campaign.sh > /work/main/results/campaign.pid
# and, before a session ends, stop it without losing a step (each unit writes a checkpoint
# where it stops, and the sweep exits 130, which ends this script too):
#   kill -TERM -- -$(cat /work/main/results/campaign.pid)
# (CAMPAIGN_CODE, CAMPAIGN_PYTHON and CAMPAIGN_RESULTS replace the three paths below in its test.)
set -u
cd "${CAMPAIGN_CODE:-/work/camp}"  # python -m puts the working folder first: the frozen code runs
PY=${CAMPAIGN_PYTHON:-/work/main/.venv/bin/python}
R=${CAMPAIGN_RESULTS:-/work/main/results}
mkdir -p "$R"
for preset in table1-ant-humanoid paper-schedule-walker2d fixed-rank-power; do
  echo "== $(date -u +%FT%TZ) $preset"
  $PY -m adarl.cli.main sweep "$preset" --out "$R/$preset" --workers 2 --no-progress
  code=$?
  echo "== $(date -u +%FT%TZ) $preset exited $code"
  # stopped (Ctrl-C, SIGTERM: 130) or refused (bad input: 2): go no further
  if [ "$code" -eq 130 ] || [ "$code" -eq 2 ]; then exit "$code"; fi
  # issue 34 §3.4 on Walker2d's 3M policies (paper-schedule-walker2d.md, "Robustness at 3M"),
  # once every unit is done, before a new machine can lose them. A stopped evaluation starts
  # again at the next resume; a finished one (both suites/paper.csv written) is not repeated.
  W=$R/paper-schedule-walker2d/walker2d
  if [ "$preset" = paper-schedule-walker2d ] && [ "$code" -eq 0 ] &&
    { [ ! -f "$W/adarl_rank_rule-cumulative/seeds-0-4/suites/paper.csv" ] ||
      [ ! -f "$W/sac/seeds-0-4/suites/paper.csv" ]; }; then
    echo "== $(date -u +%FT%TZ) robustness at 3M (paper suite, 5 episodes a point)"
    $PY -m adarl.cli.main evaluate "$W/adarl_rank_rule-cumulative/seeds-0-4" "$W/sac/seeds-0-4" \
      --suite paper --episodes 5 --workers 2 --no-progress
    code=$?
    echo "== $(date -u +%FT%TZ) robustness exited $code"
    if [ "$code" -eq 130 ] || [ "$code" -eq 143 ]; then exit "$code"; fi  # stopped
  fi
done
