#!/usr/bin/env bash
# Reproduce the paper's Figure 2 on cheetah_dir_sparse: 6 presets x 3 seeds (+ the task-aware reference,
# which learns the dense cheetah_dir and is deployed on cheetah_dir_sparse), plus the extra rows of
# research/turnaround/fig2_presets.py (oracle_rh_prior5). See docs/results.md and research/turnaround/notebook.md.
# The presets whose turn-around is in question run first, so a partial grid already answers it.
#   bash research/turnaround/reproduce_fig2.sh [FRAMES] [OUT]
# Resumable: rerun the same command after an interruption (it passes --resume when OUT exists).
set -euo pipefail
cd "$(dirname "$0")/../.."
FRAMES=${1:-4000000}
OUT=${2:-runs/fig2}
RESUME=()
[ -f "$OUT/grid.json" ] && RESUME=(--resume)
MUJOCO_GL=disable .venv/bin/python evaluation/run.py \
  --import research/turnaround/fig2_presets.py \
  --agents oracle_rh oracle_rh_prior5 hyperx varibad_rh oracle_rs oracle varibad \
  --tasks cheetah_dir_sparse --seeds 0 1 2 \
  --frames "$FRAMES" --eval-every $((FRAMES / 20)) --eval-tasks 20 \
  --config research/turnaround/fig2.toml --workers 2 --out "$OUT" "${RESUME[@]}"
