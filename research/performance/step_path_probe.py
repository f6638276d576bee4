"""Does the per-step path as plain functions pay? Rollout collection with it and with nn.Module calls.

    python research/performance/step_path_probe.py [--preset hyperx] [--rounds 12] [--num-envs 16] [--out FILE]

The trainer's rollout calls `ActorCritic.step` (actor and critic layers as plain functions, one call)
and, for variBAD beliefs, `VariationalEncoder.step` (`gru_cell` and `F.linear`). The module path is
what they replace: `mean_std` + `value`, and the encoder's `nn.GRU` and `nn.Linear` modules. This probe
builds one trainer and collects `--rounds` pairs of rollouts, alternating the two paths (so the
machine's speed drift falls on both), each on its own trainer built from the same seed; it checks that both
paths give identical rollouts and reports the median time ratio. Run it with nothing else on the CPU.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import time
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "disable")

import torch  # noqa: E402

from hyperstate import agents  # noqa: E402
from hyperstate.agents.beliefs import VariationalEncoder  # noqa: E402
from hyperstate.agents.ppo import ActorCritic  # noqa: E402
from hyperstate.agents.trainer import Trainer  # noqa: E402


def module_step(model: ActorCritic, state: torch.Tensor, features: torch.Tensor):
    mean, std = model.mean_std(state, features)
    return mean, std, model.value(state, features)


def module_encoder_step(encoder: VariationalEncoder, h, action, reward, next_state):
    out, h = encoder.gru(encoder.embed(action, reward, next_state)[None], h[None])
    mean, logvar = encoder.head(out[0]).chunk(2, dim=-1)
    return h[0], mean, logvar


PATHS = {
    "functions": (ActorCritic.step, VariationalEncoder.step),
    "modules": (module_step, module_encoder_step),
}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--preset", default="hyperx")
    parser.add_argument("--task", default="cheetah_dir_sparse")
    parser.add_argument("--rounds", type=int, default=12)
    parser.add_argument("--num-envs", type=int, default=16)
    parser.add_argument("--out", type=Path, default=None, help="default bench/results/step_path_<preset>.json")
    args = parser.parse_args()
    # Two trainers built from one seed: the same state, each advanced by one path.
    overrides = {"torch_threads": 1, "ppo.num_envs": args.num_envs}
    trainers = {name: Trainer(agents.make(args.preset, **overrides), args.task, 10**7) for name in PATHS}
    seconds: dict[str, list[float]] = {name: [] for name in PATHS}
    identical = True
    try:
        for _ in range(args.rounds):
            rollouts = {}
            for name, (step, encoder_step) in PATHS.items():
                ActorCritic.step, VariationalEncoder.step = step, encoder_step
                start = time.perf_counter()
                trainers[name].collect()
                seconds[name].append(time.perf_counter() - start)
                rollouts[name] = (trainers[name].rollout.actions.clone(), trainers[name].rollout.features.clone())
            identical &= all(torch.equal(a, b) for a, b in zip(*rollouts.values(), strict=True))
    finally:
        ActorCritic.step, VariationalEncoder.step = PATHS["functions"]
    # The first round warms caches and allocators; pairs are compared round by round.
    ratios = [f / m for f, m in zip(seconds["functions"][1:], seconds["modules"][1:], strict=True)]
    frames = trainers["functions"].rollout.actions[..., 0].numel()
    result = {
        "preset": args.preset,
        "task": args.task,
        "rounds": args.rounds,
        "frames_per_rollout": frames,
        "identical_rollouts": identical,
        "collect_frames_per_second": {k: round(frames / statistics.median(v[1:])) for k, v in seconds.items()},
        "functions_over_modules_time": {
            "median": round(statistics.median(ratios), 3),
            "min": round(min(ratios), 3),
            "max": round(max(ratios), 3),
        },
    }
    out = args.out or Path(f"bench/results/step_path_{args.preset}.json")
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(result, indent=2) + "\n")
    print(json.dumps(result, indent=2))


if __name__ == "__main__":
    main()
