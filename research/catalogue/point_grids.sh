#!/usr/bin/env bash
# The point tasks' grids (research/catalogue/README.md, "The point tasks' grids"), one lane per task, the
# parts in the order they run, as a lane of research/catalogue/lane.sh: each part is its own OUT under
# runs/<task>/ and resumes where it stopped (finished cells are skipped). Two lanes side by side on 2 cores:
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
  point_robot_sparse|point_treasure_sparse) ;;
  *) echo "point_grids.sh: unknown task $TASK" >&2; exit 2 ;;
esac
exec bash research/catalogue/lane.sh "$TASK" 2e7 "rl2|2" "task_supervised|0 1 2"
