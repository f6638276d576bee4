#!/usr/bin/env bash
# The Figure-2 grid at the turn-around's budget and settings (docs/turnaround.md, H16 + H18): the seed
# presets with bench/fig2.toml, the learning rate on the reference's 5e7-frame schedule
# (turnaround/lr_horizon_5e7.toml), the reference code's PPO and exploration noise (turnaround/icml_ppo.toml)
# and its actor-critic network (turnaround/reference_network.toml), and `oracle_rh` with its hyper-state
# bonus weighted 20 instead of the seed paper's 10 (turnaround/hyperstate_weight_20.toml: H20, tuned on seeds
# 0-2 of this task, where 10 ran one way in 3 of 3); every deviation is listed in docs/results.md.
# `oracle_rh_rs` (bench/fig2_presets.py: the oracle with hyperx's bonuses, r_h + r_s) is a row beyond the
# paper's (docs/turnaround.md, H19). The task-aware reference is one of the agents (it learns the dense task),
# so the grid can run in parts — some agents or seeds per machine or session — merged with evaluation/merge.py:
#   bash bench/reproduce_fig2_turnaround.sh [FRAMES] [OUT]                    # the whole grid
#   AGENTS="hyperx" SEEDS="2" bash bench/reproduce_fig2_turnaround.sh 20000000 runs/part_hyperx_s2
#   .venv/bin/python evaluation/merge.py --into docs/results/fig2_turnaround runs/part_*
# Resumable: rerun the same command after an interruption (it passes --resume when OUT exists).
# WORKERS=2 runs two cells at once (one physics thread each, bench/fig2.toml).
set -euo pipefail
cd "$(dirname "$0")/.."
FRAMES=${1:-20000000}
OUT=${2:-runs/fig2_turnaround}
read -r -a AGENT_LIST <<< "${AGENTS:-oracle_rh hyperx oracle_rh_rs varibad_rh oracle_rs oracle varibad task_aware}"
read -r -a SEED_LIST <<< "${SEEDS:-0 1 2}"
RESUME=()
[ -f "$OUT/grid.json" ] && RESUME=(--resume)
MUJOCO_GL=disable .venv/bin/python evaluation/run.py --import bench/fig2_presets.py \
  --agents "${AGENT_LIST[@]}" --tasks cheetah_dir_sparse --seeds "${SEED_LIST[@]}" \
  --frames "$FRAMES" --eval-every $((FRAMES / 10)) --eval-tasks 20 --no-reference \
  --config bench/fig2.toml bench/turnaround/lr_horizon_5e7.toml bench/turnaround/icml_ppo.toml \
  bench/turnaround/reference_network.toml bench/turnaround/hyperstate_weight_20.toml \
  --workers "${WORKERS:-1}" --out "$OUT" "${RESUME[@]}"
