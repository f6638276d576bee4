"""Components from the user's own file: a belief registered here is used by a preset, trained, checkpointed,
resumed, saved and loaded; registration errors are clear."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from hyperstate import agents, evaluation, suite
from hyperstate.agents import beliefs, bonuses

TINY = {"ppo.num_envs": 4, "ppo.rollout_length": 25}
TASK_KWARGS = {"episode_length": 25, "episodes_per_task": 2}


class RewardTrace:
    """A belief of the user's own: an exponentially decaying trace of the rewards seen in the BAMDP episode."""

    feature_dim = 1

    @classmethod
    def build(cls, *, params, **_):
        if set(params) != {"decay"} or not 0 < params["decay"] < 1:
            raise ValueError(f"reward trace: params must be {{'decay': 0 < d < 1}}, got {params}")
        return cls(params["decay"])

    def __init__(self, decay: float):
        self.decay = decay

    def initial_state(self, n, obs):
        return torch.zeros(n, 1)

    def update(self, state, transition):
        return self.decay * state + (1 - self.decay) * transition.reward

    def reset_where(self, state, mask, obs):
        return torch.where(mask[:, None], torch.zeros_like(state), state)

    def features(self, state):
        return state

    def policy_parameters(self):
        return []

    def sequence_features(self, rollout, env_index):
        return rollout.features[:, env_index]

    def train_step(self, trajectories):
        return {}

    def state_dict(self):
        return {}

    def load_state_dict(self, state):
        pass


@pytest.fixture
def registered():
    agents.register_belief("test_reward_trace")(RewardTrace)
    config = agents.AgentConfig(
        belief="test_reward_trace", belief_params={"decay": 0.5}, bonuses=(agents.BonusConfig(input="hyperstate"),)
    )
    agents.register_preset("test_trace_rh", config)
    yield "test_trace_rh"
    agents.unregister_preset("test_trace_rh")
    beliefs.unregister_belief("test_reward_trace")


def _params(agent) -> list[torch.Tensor]:
    return [p.detach().clone() for p in agent.model.parameters()] + [
        p.detach().clone() for p in agent.bonuses[0].predictors.parameters()
    ]


def test_a_registered_belief_trains_checkpoints_resumes_saves_and_loads(registered, tmp_path):
    assert "test_reward_trace" in agents.list_beliefs() and registered in evaluation.agent_names()
    assert RewardTrace.trainable is False and RewardTrace.reads_true_task is False  # capabilities default off
    whole = agents.make(registered, **TINY)
    whole.train("cheetah_dir_sparse", frames=400, seed=1, task_kwargs=TASK_KWARGS, progress=False)
    first = agents.make(registered, **TINY, checkpoint_every=1)
    kwargs = {"frames": 400, "seed": 1, "task_kwargs": TASK_KWARGS, "progress": False, "checkpoint_dir": tmp_path}
    first.train("cheetah_dir_sparse", **kwargs, stop_after_iterations=2)
    resumed = agents.make(registered, **TINY, checkpoint_every=1)
    log = resumed.train("cheetah_dir_sparse", **kwargs, resume=True)
    assert [entry["iteration"] for entry in log] == [1, 2, 3, 4]
    for a, b in zip(_params(whole), _params(resumed), strict=True):
        torch.testing.assert_close(a, b, rtol=0, atol=0)
    resumed.save(tmp_path / "agent.pt")
    loaded = agents.Agent.load(tmp_path / "agent.pt")
    assert isinstance(loaded.belief, RewardTrace) and loaded.belief.decay == 0.5
    env = suite.batch("cheetah_dir_sparse", 2, seed=4, privileged=True, **TASK_KWARGS)
    obs = env.reset().observation
    a1, s1 = resumed.act(obs)
    a2, s2 = loaded.act(obs)
    np.testing.assert_array_equal(a1, a2)
    step = env.step(a1)
    _, s1 = resumed.act(step.observation, s1, reward=step.reward)
    np.testing.assert_allclose(resumed.belief_features(s1)[:, 0], 0.5 * step.reward, rtol=1e-6)


def test_component_params_are_validated_by_the_component(registered):
    with pytest.raises(ValueError, match="reward trace: params"):
        agents.make(registered, **{"belief_params.decay": 2.0}).check_task("cheetah_dir_sparse")
    with pytest.raises(ValueError, match="'oracle' component takes no params"):
        agents.make("oracle", belief_params={"x": 1}).check_task("cheetah_dir_sparse")
    with pytest.raises(ValueError, match="'rnd' bonus takes no params"):
        agents.make("oracle_rh", **{"bonuses.0.params.x": 1}).check_task("cheetah_dir_sparse")


def test_registration_errors_are_clear(registered):
    with pytest.raises(ValueError, match="already registered"):
        agents.register_belief("test_reward_trace")(RewardTrace)
    with pytest.raises(ValueError, match="already registered"):
        agents.register_preset("oracle", agents.AgentConfig())
    with pytest.raises(ValueError, match="already registered"):
        evaluation.register_agent("oracle")(lambda **_: None)

    class Incomplete:
        @classmethod
        def build(cls, **_):
            return cls()

    with pytest.raises(TypeError, match="lacks initial_state, update"):
        agents.register_belief("test_incomplete")(Incomplete)
    with pytest.raises(TypeError, match="lacks reward, update"):
        agents.register_bonus("test_incomplete")(Incomplete)
    with pytest.raises(ValueError, match=r"unknown belief 'test_reward_trce' \(did you mean test_reward_trace\?\)"):
        agents.register_preset("test_typo", agents.AgentConfig(belief="test_reward_trce"))
    with pytest.raises(ValueError, match=r"unknown bonus kind 'rdn' \(did you mean rnd\?\)"):
        agents.make("oracle_rh", **{"bonuses.0.kind": "rdn"})
    assert "test_incomplete" not in agents.list_beliefs() and "test_incomplete" not in bonuses.list_bonuses()
    with pytest.raises(ValueError, match=r"unknown agent 'test_trace_hr' \(did you mean test_trace_rh"):
        evaluation.make_agent("test_trace_hr")
