#!/usr/bin/env bash
# The Figure-2 grid's reference-code rows: `hyperx_icml` and `oracle_rh_icml` (agents/presets.py: the
# reference code's ICML configurations for sparse cheetah-dir) at the grid's budget, with no deviation
# from the presets except one physics thread per cell (two cells share the 2 cores).
# Compare with bench/reproduce_fig2.sh's rows at the same FRAMES (docs/turnaround.md). Seeds 0-2 by
# default (SEEDS="0" for one seed each); WORKERS=2 when nothing else runs.
#   bash bench/reproduce_fig2_icml.sh [FRAMES] [OUT]
# Resumable: rerun the same command after an interruption (it passes --resume when OUT exists).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-20000000}
OUT=${2:-runs/fig2_icml}
read -r -a SEED_LIST <<< "${SEEDS:-0 1 2}"
RESUME=()
[ -f "$OUT/grid.json" ] && RESUME=(--resume)
MUJOCO_GL=disable .venv/bin/python evaluation/run.py \
  --agents hyperx_icml oracle_rh_icml --tasks cheetah_dir_sparse --seeds "${SEED_LIST[@]}" \
  --frames "$FRAMES" --eval-every $((FRAMES / 20)) --eval-tasks 20 --no-reference \
  --config bench/fig2_icml.toml --workers "${WORKERS:-1}" --out "$OUT" "${RESUME[@]}"
