#!/usr/bin/env bash
# A catalogue baseline grid (docs/results/<task>/): the presets as they are on one sparse task, 3 seeds,
# 20 held-out tasks, deterministic and sampled deployment (every record has both). The agents are the
# meta-learners of the paper and the task-aware reference; on a task with an exact belief (a privileged
# `belief` observation) also the belief oracles:
#   hyperx varibad_rh varibad rl2 task_supervised task_aware [oracle oracle_rh oracle_rs]
#
#   bash scripts/reproduce_catalogue.sh TASK FRAMES [OUT]                     # the whole grid
#   AGENTS="hyperx" SEEDS="2" bash scripts/reproduce_catalogue.sh rooms_sparse 2e7 runs/rooms_hyperx_s2
#   .venv/bin/hyperstate-merge --into docs/results/rooms_sparse runs/rooms_*
#
# FRAMES is the task's budget, fixed by its calibration (research/catalogue/README.md). Resumable: rerun the
# same command (it passes --resume when OUT exists). EVAL_EVERY sets the evaluation points (default: 10
# points over FRAMES). CONFIG=FILE passes a TOML of per-task settings (--config), named in the task's
# results with the reason; the presets' learning rate decays over ppo.lr_anneal_frames (5e7), so a budget
# above it needs one. WORKERS and PHYSICS_THREADS as in evaluation/run.py; DRY_RUN=1 prints the command.
set -euo pipefail
cd "$(dirname "$0")/.."
TASK=${1:?usage: reproduce_catalogue.sh TASK FRAMES [OUT]}
FRAMES=${2:?usage: reproduce_catalogue.sh TASK FRAMES [OUT]}
OUT=${3:-runs/catalogue/$TASK}
PY=.venv/bin/python
if [ -z "${AGENTS:-}" ]; then
  AGENTS="hyperx varibad_rh varibad rl2 task_supervised task_aware"
  if MUJOCO_GL=disable $PY -c "import sys; from hyperstate import suite
sys.exit(0 if 'belief' in suite.load(sys.argv[1], privileged=True).observation_spec() else 1)" "$TASK"; then
    AGENTS="$AGENTS oracle oracle_rh oracle_rs"
  fi
fi
read -r -a AGENT_LIST <<< "$AGENTS"
read -r -a SEED_LIST <<< "${SEEDS:-0 1 2}"
EVAL_EVERY=${EVAL_EVERY:-$($PY -c "import sys; from hyperstate.evaluation.run import frame_count
try: print(frame_count(sys.argv[1]) // 10)
except Exception: print(sys.argv[1])  # evaluation/run.py says what is wrong with it" "$FRAMES")}
EXTRA=()
[ -f "$OUT/grid.json" ] && EXTRA+=(--resume)
[ -n "${PHYSICS_THREADS:-}" ] && EXTRA+=(--physics-threads "$PHYSICS_THREADS")
[ -n "${CONFIG:-}" ] && EXTRA+=(--config "$CONFIG")
# DRY_RUN=1 prints the command instead of running it.
${DRY_RUN:+echo} env MUJOCO_GL=disable $PY evaluation/run.py \
  --agents "${AGENT_LIST[@]}" --tasks "$TASK" --seeds "${SEED_LIST[@]}" \
  --frames "$FRAMES" --eval-every "$EVAL_EVERY" --eval-tasks 20 --no-reference \
  --workers "${WORKERS:-1}" --out "$OUT" "${EXTRA[@]}"
