#!/usr/bin/env bash
# Calibration for the catalogue baselines: one seed of each agent on one task, at a budget well above
# what the best of them needs, with a learning curve dense enough to see where it flattens.
#
#   TASK=rooms_sparse AGENTS="hyperx oracle_rh oracle" bash research/catalogue/calibrate.sh [FRAMES] [OUT]
#   CONFIG=research/catalogue/gamma_0.99.toml TASK=... bash research/catalogue/calibrate.sh [FRAMES] [OUT]
#
# FRAMES defaults to 2e7 (the HyperX reference's point-robot budget; the presets' learning rate decays
# over 5e7 frames whatever the budget, so a longer run continues this one: --resume with a larger
# --frames). Each agent gets its own --out folder (OUT_<agent>), so agents run and merge independently;
# rerunning the command resumes. Plain evaluation/run.py with the presets as they are, unless CONFIG names
# an overrides file (one per-task setting, the same for every agent: --config CONFIG). A run with CONFIG
# needs its own OUT. PHYSICS_THREADS sets the cell's physics threads (1 where two runs share 2 cores).
set -euo pipefail
cd "$(dirname "$0")/../.."
: "${TASK:?set TASK to a registered task}"
FRAMES=${1:-20000000}
OUT=${2:-runs/calibration/$TASK}
read -r -a AGENT_LIST <<< "${AGENTS:-hyperx oracle_rh oracle}"
for agent in "${AGENT_LIST[@]}"; do
  out="${OUT}_${agent}"
  EXTRA=()
  [ -f "$out/grid.json" ] && EXTRA+=(--resume)
  [ -n "${CONFIG:-}" ] && EXTRA+=(--config "$CONFIG")
  [ -n "${PHYSICS_THREADS:-}" ] && EXTRA+=(--physics-threads "$PHYSICS_THREADS")
  echo "=== $agent on $TASK: start $(date -u +%FT%TZ) commit $(git rev-parse --short HEAD) config ${CONFIG:-none}"
  MUJOCO_GL=disable .venv/bin/python evaluation/run.py \
    --agents "$agent" --tasks "$TASK" --seeds "${SEED:-0}" \
    --frames "$FRAMES" --eval-every 1000000 --eval-tasks 20 --no-reference \
    --workers 1 --out "$out" "${EXTRA[@]}"
  echo "=== $agent on $TASK: end $(date -u +%FT%TZ)"
done
