#!/usr/bin/env bash
# The reference code's configurations (docs/results/fig2_icml): the `_icml` presets as they are, on
# cheetah_dir_sparse, 2e7 frames, 20 held-out tasks.
#   bash scripts/reproduce_fig2_icml.sh [FRAMES] [OUT]
#   SEEDS="0" bash scripts/reproduce_fig2_icml.sh 2e7 runs/icml_20m
# Resumable: rerun the same command after an interruption. The `_icml` presets anneal their bonuses and
# learning rate over the budget, so a finished run cannot be extended (the harness says so).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-20000000}
OUT=${2:-runs/fig2_icml}
read -r -a SEED_LIST <<< "${SEEDS:-0 1 2}"
EXTRA=()
[ -f "$OUT/grid.json" ] && EXTRA+=(--resume)
[ -n "${PHYSICS_THREADS:-}" ] && EXTRA+=(--physics-threads "$PHYSICS_THREADS")
MUJOCO_GL=disable .venv/bin/python evaluation/run.py \
  --agents hyperx_icml oracle_rh_icml --tasks cheetah_dir_sparse --seeds "${SEED_LIST[@]}" \
  --frames "$FRAMES" --eval-every 1000000 --eval-tasks 20 --no-reference \
  --workers "${WORKERS:-1}" --out "$OUT" "${EXTRA[@]}"
