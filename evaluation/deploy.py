"""Deployment: run a trained agent on held-out tasks for a whole BAMDP episode and measure it.

Online return at deployment = mean over held-out tasks of the summed reward over the BAMDP horizon,
starting from the prior belief (the agent's belief / hidden state is reset only at the BAMDP start),
with deterministic actions (the policy's mean). Also reported per inner MDP episode, plus the task's
declared deployed-exploration metrics. `deploy(..., deterministic=False)` samples actions instead, from
a fixed seed, for the stochastic policy's return next to the deterministic one.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from hyperstate import suite
from hyperstate.evaluation.probe import belief_quality

# Held-out tasks and initial states come from their own seed, the same for every agent and run.
EVAL_SEED = 987_654_321


def evaluation_tasks(task: str, n: int, seed: int = EVAL_SEED) -> np.ndarray:
    """`n` held-out task parameters from the prior; a finite prior's support is covered in turn."""
    prior = suite.task_prior(task)
    support = prior.support()
    if support is not None:
        return np.stack([support[i % len(support)] for i in range(max(n, len(support)))])
    rng = np.random.default_rng(seed)
    return np.stack([prior.sample(rng) for _ in range(n)])


@dataclasses.dataclass
class Deployment:
    """One deployment of M copies: (T, M) rewards, (T, M, ...) observations each step ended in."""

    rewards: np.ndarray
    observations: dict[str, np.ndarray]
    inner_episode: np.ndarray  # (T, M) index of the MDP episode each step belongs to
    tasks: np.ndarray  # (M, P)
    features: np.ndarray  # (T, M, F) the agent's belief features when it chose each action
    exact_belief: np.ndarray | None  # (T, M, B) the exact belief at the same moments, where the task has one

    def episode_returns(self) -> np.ndarray:
        """(K, M) return of each inner MDP episode."""
        k = int(self.inner_episode.max()) + 1
        return np.stack([(self.rewards * (self.inner_episode == i)).sum(0) for i in range(k)])


class CertaintyEquivalent:
    """A task-aware agent made Bayes-adaptive by certainty equivalence.

    At every step it is shown the exact belief's most probable task (ties go to the first support
    point) in place of the true task, so it commits to a guess, acts on it, and switches as soon as the
    belief does. Its online return is achievable without knowing the task: a lower bound on the
    Bayes-optimal return, measured with the real cost of acting on a wrong guess (for cheetah-dir:
    leaving the zone the wrong way and turning back), where `bayes_optimal_estimate` is an optimistic
    upper estimate. Needs a task with a finite prior and an exact belief over its support.
    """

    def __init__(self, agent, support: np.ndarray):
        self.agent = agent
        self.support = np.asarray(support)

    def act(self, obs: dict[str, np.ndarray], state=None, deterministic: bool = True, reward=None):
        guess = dict(obs)
        guess["task"] = self.support[np.argmax(obs["belief"], axis=-1)].astype(obs["task"].dtype)
        return self.agent.act(guess, state, deterministic=deterministic, reward=reward)

    def belief_features(self, state) -> np.ndarray:
        return self.agent.belief_features(state)


def reads_true_task(agent) -> bool:
    """Whether `agent`'s policy is conditioned on the true task (a task-aware reference, not a
    meta-learner): its optional `reads_true_task` attribute (evaluation/protocol.py)."""
    return bool(getattr(agent, "reads_true_task", False))


def certainty_equivalent_metrics(
    agent, task: str, tasks: np.ndarray, episodes_per_task: int | None = None
) -> dict | None:
    """Deployment metrics of `CertaintyEquivalent(agent)`, or None where the task has no finite prior
    or no exact belief (then certainty equivalence is not defined here)."""
    support = suite.task_prior(task).support()
    if support is None or suite.load(task, seed=0, privileged=True).task.prior_belief() is None:
        return None
    return deployment_metrics(deploy(CertaintyEquivalent(agent, support), task, tasks, episodes_per_task), task)


def deploy(
    agent,
    task: str,
    tasks: np.ndarray,
    episodes_per_task: int | None = None,
    seed: int = EVAL_SEED,
    *,
    deterministic: bool = True,
) -> Deployment:
    """Deploys `agent` on each of `tasks` for one BAMDP episode. Deterministic actions by default; with
    `deterministic=False` actions are sampled, from torch's RNG seeded with `seed` inside a fork of it
    (the caller's RNG state is untouched, so deploying never changes a training run)."""
    import torch

    with torch.random.fork_rng():
        torch.manual_seed(seed)
        return _deploy(agent, task, tasks, episodes_per_task, seed, deterministic)


def _deploy(agent, task, tasks, episodes_per_task, seed, deterministic) -> Deployment:
    kwargs = {} if episodes_per_task is None else {"episodes_per_task": episodes_per_task}
    env = suite.batch(task, len(tasks), seed=seed, privileged=True, num_threads=1, **kwargs)
    env.set_tasks(tasks)
    out = env.reset()
    state, rewards, observations, inner, features, exact = None, [], [], [], [], []
    while True:
        inner.append(out.observation["inner_episode"][:, 0].copy())
        exact.append(out.observation.get("belief"))
        action, state = agent.act(
            out.observation, state, deterministic=deterministic, reward=None if state is None else out.reward
        )
        # Agents without belief features (an optional part of the protocol) give the probe nothing.
        has_features = hasattr(agent, "belief_features")
        features.append(agent.belief_features(state) if has_features else np.zeros((len(tasks), 0)))
        out = env.step(action)
        rewards.append(out.reward)
        observations.append(out.final_observation)
        if out.last.all():
            break
        if out.last.any():
            raise RuntimeError("deployments must end together (all copies share the BAMDP horizon)")
    env.close()
    stacked = {k: np.stack([o[k] for o in observations]) for k in observations[0]}
    return Deployment(
        np.stack(rewards),
        stacked,
        np.stack(inner).astype(int),
        np.asarray(tasks),
        np.stack(features),
        None if exact[0] is None else np.stack(exact),
    )


def exploration_metric_means(
    task: str, observations: dict[str, np.ndarray], rewards: np.ndarray, tasks: np.ndarray
) -> dict[str, float | None] | None:
    """The task's declared exploration metrics of M deployments, each averaged over the deployments where
    it is defined (None where it is nowhere); None if the task declares none."""
    declared = suite.exploration_metrics(task)
    if declared is None:
        return None
    means = {}
    for name, values in declared(observations, rewards, tasks).items():
        values = np.asarray(values, dtype=float)
        finite = values[np.isfinite(values)]
        means[name] = float(finite.mean()) if len(finite) else None
    return means


def deployment_metrics(deployment: Deployment, task: str, probe: bool = False) -> dict:
    """Online return (mean over tasks), per-episode returns, the task's exploration metrics and, with
    `probe`, the belief-quality probe (tasks with an exact belief)."""
    returns = deployment.rewards.sum(0)
    metrics: dict = {
        "online_return": float(returns.mean()),
        "online_return_per_task": returns.tolist(),
        "episode_returns": deployment.episode_returns().mean(1).tolist(),
    }
    declared = exploration_metric_means(task, deployment.observations, deployment.rewards, deployment.tasks)
    if declared is not None:
        metrics["exploration_metric_names"] = sorted(declared)
        metrics.update(declared)
    if probe and deployment.exact_belief is not None and deployment.rewards.shape[1] >= 2:
        metrics.update(belief_quality(deployment.features, deployment.exact_belief))
    return metrics
