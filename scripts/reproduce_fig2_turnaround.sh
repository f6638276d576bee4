#!/usr/bin/env bash
# The turn-around grid (docs/results/fig2_turnaround): the validated presets as they are (rl2 and task_supervised
# included), on cheetah_dir_sparse,
# 3 seeds, 2e7 frames, 20 held-out tasks. The task-aware reference is one of the agents, so the grid can run in
# parts (some agents or seeds per machine or session), merged with hyperstate-merge:
#   bash scripts/reproduce_fig2_turnaround.sh [FRAMES] [OUT]                     # the whole grid
#   AGENTS="hyperx" SEEDS="2" bash scripts/reproduce_fig2_turnaround.sh 2e7 runs/part_hyperx_s2
#   .venv/bin/hyperstate-merge --into docs/results/fig2_turnaround runs/part_*
# Resumable: rerun the same command after an interruption (it passes --resume when OUT exists); a larger
# FRAMES extends a finished grid. WORKERS=2 runs two cells at once; PHYSICS_THREADS sets each cell's physics
# threads (default: the cores shared out among the workers; results do not depend on it).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-20000000}
OUT=${2:-runs/fig2_turnaround}
read -r -a AGENT_LIST <<< "${AGENTS:-oracle_rh hyperx varibad_rh oracle_rs oracle varibad rl2 task_supervised task_aware}"
read -r -a SEED_LIST <<< "${SEEDS:-0 1 2}"
EXTRA=()
[ -f "$OUT/grid.json" ] && EXTRA+=(--resume)
[ -n "${PHYSICS_THREADS:-}" ] && EXTRA+=(--physics-threads "$PHYSICS_THREADS")
MUJOCO_GL=disable .venv/bin/python evaluation/run.py \
  --agents "${AGENT_LIST[@]}" --tasks cheetah_dir_sparse --seeds "${SEED_LIST[@]}" \
  --frames "$FRAMES" --eval-every 2000000 --eval-tasks 20 --no-reference \
  --workers "${WORKERS:-1}" --out "$OUT" "${EXTRA[@]}"
