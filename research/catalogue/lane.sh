#!/usr/bin/env bash
# One lane of a catalogue grid: parts of `scripts/reproduce_catalogue.sh TASK FRAMES`, one after another,
# each part its own OUT (runs/<task>/<part>), resumable (a rerun skips finished cells and resumes the
# running one from its last evaluation point). Two lanes side by side on 2 cores, from a worktree:
#
#   nohup setsid bash research/catalogue/lane.sh rooms_sparse 5e7 "oracle_rh|1 2" "hyperx|1 2" \
#       >> runs/logs/laneA.log 2>&1 < /dev/null &
#
# A part is "AGENTS|SEEDS". Every part evaluates every 1M frames, as the calibrations do, so that a
# calibration's seed-0 cells merge into the grid (research/catalogue/README.md):
#
#   .venv/bin/hyperstate-merge --into docs/results/TASK docs/results/calibration/TASK runs/TASK/*
set -u
cd "$(dirname "$0")/../.."
TASK=${1:?usage: lane.sh TASK FRAMES "AGENTS|SEEDS" ...}
FRAMES=${2:?usage: lane.sh TASK FRAMES "AGENTS|SEEDS" ...}
shift 2
[ $# -gt 0 ] || { echo "lane.sh: name at least one part, \"AGENTS|SEEDS\"" >&2; exit 2; }
for part in "$@"; do
  IFS='|' read -r agents seeds <<< "$part"
  if [ -z "$agents" ] || [ -z "$seeds" ]; then
    echo "lane.sh: part \"$part\" is not \"AGENTS|SEEDS\"" >&2; exit 2
  fi
  out="runs/$TASK/$(echo "$agents" | tr ' ' '+')_s$(echo "$seeds" | tr -d ' ')"
  echo "### $(date -u +%FT%TZ) start $TASK $out: $agents, seeds $seeds, $FRAMES frames, commit $(git rev-parse --short HEAD)"
  EVAL_EVERY=${EVAL_EVERY:-1000000} PHYSICS_THREADS=${PHYSICS_THREADS:-1} AGENTS="$agents" SEEDS="$seeds" \
    bash scripts/reproduce_catalogue.sh "$TASK" "$FRAMES" "$out"
  rc=$?  # before the echo's $(date), which resets $?
  echo "### $(date -u +%FT%TZ) end $TASK $out rc=$rc"
done
