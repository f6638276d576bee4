#!/usr/bin/env bash
# The point tasks' grids (research/catalogue/README.md, "The point tasks' grids"), one lane per task, the
# parts in the order they run; each part is its own OUT under runs/<task>/ and resumes where it stopped
# (reproduce_catalogue.sh passes --resume; finished cells are skipped). Two lanes side by side on 2 cores:
#
#   nohup setsid bash research/catalogue/point_grids.sh point_robot_sparse >> runs/logs/laneA.log 2>&1 < /dev/null &
#   nohup setsid bash research/catalogue/point_grids.sh point_treasure_sparse >> runs/logs/laneB.log 2>&1 < /dev/null &
#
# The evaluation points are the calibration's (every 1M frames), whose seed-0 cells the grids merge
# (docs/results/calibration/<task>/).
set -u
cd "$(dirname "$0")/../.."
TASK=${1:?usage: point_grids.sh point_robot_sparse|point_treasure_sparse}
# The grids are complete: every part is merged into docs/results/<task>/. These are the last parts to
# finish (rl2 seed 2 and task_supervised, on both tasks); running them again reproduces those cells.
case "$TASK" in
  point_robot_sparse|point_treasure_sparse)
    PARTS=("rl2_s2|rl2|2" "task_supervised|task_supervised|0 1 2") ;;
  *) echo "point_grids.sh: unknown task $TASK" >&2; exit 2 ;;
esac
for part in "${PARTS[@]}"; do
  IFS='|' read -r out agents seeds <<< "$part"
  echo "### $(date -u +%FT%TZ) start $TASK $out: $agents, seeds $seeds, commit $(git rev-parse --short HEAD)"
  EVAL_EVERY=1000000 PHYSICS_THREADS=1 AGENTS="$agents" SEEDS="$seeds" \
    bash scripts/reproduce_catalogue.sh "$TASK" 2e7 "runs/$TASK/$out"
  rc=$?  # before the echo's $(date), which resets $?
  echo "### $(date -u +%FT%TZ) end $TASK $out rc=$rc"
done
