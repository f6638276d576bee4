"""Fidelity options: the reference code's choices, each a config field, each checked against a known answer."""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from hyperstate import agents
from hyperstate.agents.bonuses import BonusInput, EnsembleRND, InputSelector, PriorNetwork
from hyperstate.agents.config import BonusConfig, PPOConfig
from hyperstate.agents.normalization import ReturnScaler
from hyperstate.agents.ppo import ActorCritic, _minibatches, ppo_update, value_loss
from hyperstate.agents.presets import PAPER_PPO
from hyperstate.agents.trainer import Trainer, bonus_anneal_factor, combine_rewards

TINY = {"ppo.num_envs": 4, "ppo.rollout_length": 50, "vae.batch_trajectories": 2}


def _batch(next_state: torch.Tensor, features: torch.Tensor) -> BonusInput:
    m = next_state.shape[0]
    return BonusInput(torch.zeros(m, 1), torch.zeros(m, 1), torch.zeros(m, 1), next_state, features, features)


def test_raw_rnd_inputs_reach_the_networks_unnormalised():
    config = BonusConfig(input="hyperstate", input_norm="none")
    rnd = EnsembleRND(InputSelector("hyperstate", [0], 2), config, torch.Generator().manual_seed(0), "raw")
    x = torch.tensor([[30.0], [-12.0], [0.5]])
    belief = torch.tensor([[0.5, 0.5], [1.0, 0.0], [0.0, 1.0]])
    inputs = torch.cat([x, belief], -1)
    want = (rnd.predictors[0](inputs) - rnd.priors[0](inputs)).pow(2).mean(-1)
    torch.testing.assert_close(rnd.reward(_batch(x, belief)), want)
    # The default divides by the running std and clips at ±5: 30 m and 300 m look alike.
    running = EnsembleRND(InputSelector("hyperstate", [0], 2), BonusConfig(), torch.Generator().manual_seed(0), "n")
    running.input_stats.update(np.random.default_rng(0).normal(0, 1, (1000, 3)))
    far = running.value(_batch(torch.tensor([[30.0], [300.0]]), torch.tensor([[0.5, 0.5], [0.5, 0.5]])))
    assert far[0] == far[1]


def test_prior_scaled_by_weights_or_by_output():
    parts = [1, 2]
    torch.manual_seed(3)
    plain = PriorNetwork(parts, BonusConfig(prior_scale=1.0))
    torch.manual_seed(3)
    by_output = PriorNetwork(parts, BonusConfig(prior_scale=5.0))
    torch.manual_seed(3)
    by_weights = PriorNetwork(parts, BonusConfig(prior_scale=5.0, prior_scaling="weights"))
    for p, w in zip(plain.parameters(), by_weights.parameters(), strict=True):
        torch.testing.assert_close(w, 5.0 * p)  # every weight and bias, as the reference code
    x = torch.randn(8, 3)
    torch.testing.assert_close(by_output(x), 5.0 * plain(x))
    # Our body layers start with zero biases, so scaling the weights scales the body's output by 5^3 on
    # top of the scaled embedding (weights and biases): far more than 5.
    ratio = (by_weights(x).norm() / plain(x).norm()).item()
    assert 5.0**3 < ratio <= 5.0**4 * 1.0001


def test_bonus_clip_and_per_bonus_annealing_in_eq_4():
    rng = np.random.default_rng(0)
    extrinsic, b1, b2 = rng.normal(0, 1, (6, 2)), 50 * rng.random((6, 2)), rng.random((6, 2))
    b1[3, 1] = 5_000.0  # one outlier: after normalisation it stays far beyond the clip
    lasts = np.zeros((6, 2), bool)

    def combine(**kwargs):
        scalers = [ReturnScaler(2, 0.9) for _ in range(3)]
        return combine_rewards(
            extrinsic, [b1, b2], weights=[2.0, 3.0], lasts=lasts, ext_scaler=scalers[0],
            bonus_scalers=scalers[1:], reward_clip=10.0, **kwargs,
        )  # fmt: skip

    plain, plain_scaled = combine(anneal=1.0)
    clipped, clipped_scaled = combine(anneal=[0.5, 0.25], bonus_clips=[1.5, None])
    assert plain_scaled[0].max() > 1.5
    np.testing.assert_array_equal(clipped_scaled[0], np.clip(plain_scaled[0], -1.5, 1.5))
    np.testing.assert_array_equal(clipped_scaled[1], plain_scaled[1])
    ext = plain - 2.0 * plain_scaled[0] - 3.0 * plain_scaled[1]
    np.testing.assert_allclose(clipped, ext + 0.5 * 2.0 * clipped_scaled[0] + 0.25 * 3.0 * clipped_scaled[1])


def test_anneal_schedules():
    fast = BonusConfig(anneal_until=0.5)
    constant = BonusConfig()
    assert bonus_anneal_factor(fast, False, 0.25) == 0.5
    assert bonus_anneal_factor(fast, True, 0.75) == 0.0  # its own schedule wins over the agent's
    assert bonus_anneal_factor(constant, True, 0.25) == 0.75  # the agent anneals every bonus over the run
    assert bonus_anneal_factor(constant, False, 0.9) == 1.0
    with pytest.raises(ValueError, match="anneal_until"):
        BonusConfig(anneal_until=0.0)


def _rollout(t_len: int = 6, n: int = 4) -> SimpleNamespace:
    g = torch.Generator().manual_seed(0)
    return SimpleNamespace(
        policy_state=torch.randn(t_len, n, 3, generator=g),
        features=torch.randn(t_len, n, 2, generator=g),
        actions=torch.randn(t_len, n, 2, generator=g),
        logprobs=torch.randn(t_len, n, generator=g) - 2.0,
        advantages=3.0 + 2.0 * torch.randn(t_len, n, generator=g),
        returns=torch.randn(t_len, n, generator=g)[..., None],  # (T, N, value heads)
        values=torch.randn(t_len, n, generator=g)[..., None],
    )


class _StoredFeatures:
    def sequence_features(self, rollout, idx):
        return rollout.features[:, idx]


def test_transition_minibatches_partition_the_rollout():
    rollout = _rollout()
    config = PPOConfig(minibatch_unit="transitions", minibatches=3)
    batches = list(_minibatches(rollout, _StoredFeatures(), config, torch.Generator().manual_seed(1)))
    assert [b[0].shape for b in batches] == [(8, 3)] * 3
    seen = torch.cat([b[1] for b in batches])  # features: every transition exactly once
    assert sorted(map(tuple, seen.tolist())) == sorted(map(tuple, rollout.features.reshape(-1, 2).tolist()))
    by_env = PPOConfig(minibatch_unit="envs", minibatches=2)
    envs = list(_minibatches(rollout, _StoredFeatures(), by_env, torch.Generator().manual_seed(1)))
    assert [b[0].shape for b in envs] == [(6, 2, 3)] * 2  # whole env sequences


def test_transition_minibatches_refuse_a_belief_trained_through_time():
    with pytest.raises(ValueError, match="'recurrent' belief is trained through time"):
        agents.make("rl2", **{"ppo.minibatch_unit": "transitions"}).check_task("cheetah_dir_sparse")


def _update(config: PPOConfig) -> list[torch.Tensor]:
    torch.manual_seed(0)
    model = ActorCritic(3, 2, 2, config)
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-3)
    ppo_update(model, _StoredFeatures(), optimizer, _rollout(), config, torch.Generator().manual_seed(2))
    return [p.detach().clone() for p in model.parameters()]


def test_whole_batch_advantage_normalisation():
    # With one minibatch, normalising per minibatch and over the batch are the same computation.
    one = {"minibatches": 1, "epochs": 1}
    per_one = _update(PPOConfig(**one, advantage_norm="minibatch"))
    for a, b in zip(per_one, _update(PPOConfig(**one, advantage_norm="batch")), strict=True):
        torch.testing.assert_close(a, b)
    # With several, they differ.
    per_minibatch = _update(PPOConfig(minibatches=4, advantage_norm="minibatch"))
    whole = _update(PPOConfig(minibatches=4, advantage_norm="batch"))
    assert any(not torch.equal(a, b) for a, b in zip(per_minibatch, whole, strict=True))


def test_clipped_huber_value_loss_by_hand():
    config = PPOConfig(value_loss="clipped_huber", clip=0.1)
    value, returns, old = torch.tensor([1.0, 0.0, 5.0]), torch.tensor([0.0, 3.0, 5.05]), torch.tensor([0.5, 0.0, 5.0])

    def huber(a, b):
        d = abs(a - b)
        return 0.5 * d * d if d < 1 else d - 0.5

    # Clipped predictions: 0.6 (moved 0.5 → 0.1), 0.0 (unchanged), 5.0.
    want = 0.5 * np.mean([max(huber(1.0, 0.0), huber(0.6, 0.0)), huber(0.0, 3.0), huber(5.0, 5.05)])
    one_head = value[:, None], returns[:, None], old[:, None]  # (batch, value heads)
    assert value_loss(*one_head, config).item() == pytest.approx(want)
    assert value_loss(*one_head, PPOConfig(value_loss="mse")).item() == pytest.approx(0.5 * np.mean([1.0, 9.0, 0.0025]))
    # Two heads: the sum of each head's loss.
    two = [torch.stack([t, 2 * t], dim=-1) for t in (value, returns, old)]
    want_second = 0.5 * np.mean([max(huber(2.0, 0.0), huber(1.1, 0.0)), huber(0.0, 6.0), huber(10.0, 10.1)])
    assert value_loss(*two, config).item() == pytest.approx(want + want_second)


def test_control_cost_on_the_sampled_action():
    trainer = Trainer(agents.make("oracle", **TINY), "cheetah_dir_sparse", frames=200)
    actions = np.array([[[0.5, -0.5, 0, 0, 0, 0], [1.5, -2.0, 0, 0, 0, 0.3]]])  # (T=1, N=2, 6)
    np.testing.assert_allclose(trainer.excess_action_energy(actions), [[0.0, (2.25 - 1.0) + (4.0 - 1.0)]])
    # In training it lowers the reward PPO sees by coef × that excess (and only there).
    costly = agents.make("oracle", **TINY, **{"ppo.sampled_action_cost": 0.05, "ppo.init_log_std": 1.0})
    free = agents.make("oracle", **TINY, **{"ppo.sampled_action_cost": 0.0, "ppo.init_log_std": 1.0})
    a = costly.train("cheetah_dir_sparse", frames=200, seed=0, progress=False)[0]
    b = free.train("cheetah_dir_sparse", frames=200, seed=0, progress=False)[0]
    assert a["reward/extrinsic_mean"] == b["reward/extrinsic_mean"]  # the task's reward, logged before
    assert a["ppo/value_loss"] != b["ppo/value_loss"]


def test_icml_presets_are_the_reference_configurations():
    hyperx = agents.get_preset("hyperx_icml")
    assert [(b.kind, b.input, b.weight) for b in hyperx.bonuses] == [
        ("rnd", "hyperstate", 0.1),
        ("vae_error", "belief", 1.0),
    ]
    rnd = hyperx.bonuses[0]
    assert (rnd.input_norm, rnd.prior_scaling, rnd.prior_scale, rnd.updates_per_iteration) == (
        "none",
        "weights",
        10.0,
        1,
    )
    assert hyperx.anneal_bonus and hyperx.belief == "varibad"
    assert rnd.train_on == "replay"  # its inputs drawn from the VAE's buffer, latents recomputed
    assert hyperx.vae.buffer_trajectories == 10_000  # the reference's; the seed presets keep 1,000
    assert hyperx.ppo.entropy_coef == 1e-4 and hyperx.ppo.sampled_action_cost == 0.05
    oracle = agents.get_preset("oracle_rh_icml")
    (rnd,) = oracle.bonuses
    assert (rnd.weight, rnd.prior_scale, rnd.clip, rnd.buffer_size, rnd.input_norm) == (
        5.0,
        5.0,
        10.0,
        10_000_000,
        "none",
    )
    assert rnd.train_on == "rollout"  # the reference's oracle keeps its own buffer of (state, belief) inputs
    for preset in (hyperx, oracle):
        p = preset.ppo
        assert (p.minibatch_unit, p.advantage_norm, p.value_loss, p.sampled_action_cost) == (
            "transitions", "batch", "clipped_huber", 0.05,
        )  # fmt: skip
        assert (
            dataclasses.replace(
                p, minibatch_unit="envs", advantage_norm="minibatch", value_loss="mse", sampled_action_cost=0.0
            )
            == PAPER_PPO
        )  # fmt: skip  (else the seed paper's PPO)


def _replay_trainer() -> Trainer:
    # BAMDP episodes of 20 steps: a 50-step rollout stores two whole trajectories per env.
    config = {**TINY, "bonuses.0.train_on": "replay", "bonuses.0.batch_size": 16}
    return Trainer(agents.make("hyperx_icml", **config), "cheetah_dir_sparse", frames=400, seed=1,
                   task_kwargs={"episode_length": 20})  # fmt: skip


def _posterior_by_steps(encoder, states, actions, rewards, steps: int) -> torch.Tensor:
    """(mean, logvar) after `steps` transitions, the encoder stepped one transition at a time."""
    h = torch.zeros(1, encoder.hidden)
    mean = logvar = torch.zeros(1, encoder.latent_dim)
    for t in range(steps):
        h, mean, logvar = encoder.step(h, actions[None, t], rewards[None, t], states[None, t + 1])
    return torch.cat([mean, logvar], -1)[0]


def test_replayed_bonus_inputs_are_the_current_encoders_posteriors_of_stored_trajectories():
    trainer = _replay_trainer()
    trainer.collect()
    trainer.learn(0)  # stores 8 trajectories and trains the VAE once: the collected latents are now stale
    stored = trainer.state.trajectories.items
    assert len(stored) == 8
    encoder = trainer.policy.belief.encoder
    replayed = trainer.replayed_inputs(16)  # 4 steps of each of 4 trajectories
    assert replayed.next_features.shape == (16, 10) and replayed.replay is None
    stale = 0
    for row in range(16):
        # Find the stored trajectory and step this row came from (continuous states are unique).
        pair = (replayed.state[row].numpy(), replayed.next_state[row].numpy())
        matches = [
            (i, t) for i, (s, _, _, _) in enumerate(stored) for t in range(20)
            if np.array_equal(s[t], pair[0]) and np.array_equal(s[t + 1], pair[1])
        ]  # fmt: skip
        assert len(matches) == 1
        i, t = matches[0]
        s, a, r = (torch.as_tensor(x, dtype=torch.float32) for x in stored[i][:3])
        torch.testing.assert_close(replayed.action[row], a[t])
        torch.testing.assert_close(replayed.reward[row], r[t, None])
        with torch.no_grad():
            torch.testing.assert_close(replayed.features[row], _posterior_by_steps(encoder, s, a, r[:, None], t))
            want = _posterior_by_steps(encoder, s, a, r[:, None], t + 1)
        torch.testing.assert_close(replayed.next_features[row], want)
        # The rollout holds the features as collected, before the VAE update: replay recomputes them.
        env_rows = (trainer.rollout.next_state == replayed.next_state[row]).all(-1).nonzero()
        if len(env_rows):
            step, env = env_rows[0].tolist()
            stale += not torch.allclose(trainer.rollout.next_features[step, env], want)
    assert stale > 0


def test_rnd_trained_on_replay_steps_on_replayed_minibatches_only():
    config = BonusConfig(train_on="replay", updates_per_iteration=3, batch_size=8)
    belief = SimpleNamespace(feature_dim=2, trainable=True, replay_features=lambda trajectories: None)

    def build() -> EnsembleRND:
        torch.manual_seed(0)  # the networks' initial weights
        return EnsembleRND.build(config, state_columns=[0], belief=belief, generator=torch.Generator(), name="r")

    rnd, twin = build(), build()
    g = torch.Generator().manual_seed(1)
    replays = [_batch(torch.randn(8, 1, generator=g), torch.rand(8, 2, generator=g)) for _ in range(3)]
    asked = []

    def replay(n: int) -> BonusInput:
        asked.append(n)
        return replays[len(asked) - 1]

    collected = _batch(100.0 + torch.randn(64, 1, generator=g), torch.rand(64, 2, generator=g))
    rnd.update(dataclasses.replace(collected, replay=replay))
    assert asked == [8, 8, 8] and rnd.buffer_len == 0  # the collected inputs are not stored
    for minibatch in replays:  # the same three Adam steps by hand, on the replayed inputs
        loss = twin.errors(twin.normalize(twin.selector(minibatch))).mean()
        twin.optimizer.zero_grad()
        loss.backward()
        twin.optimizer.step()
    for mine, theirs in zip(rnd.predictors.parameters(), twin.predictors.parameters(), strict=True):
        torch.testing.assert_close(mine, theirs)
    # Before the belief has stored a whole trajectory (replay answers None) it steps on the rollout's rows.
    fresh = build()
    before = [p.clone() for p in fresh.predictors.parameters()]
    fresh.update(dataclasses.replace(collected, replay=lambda n: None))
    assert fresh.buffer_len == 0
    assert any(not torch.equal(b, p) for b, p in zip(before, fresh.predictors.parameters(), strict=True))


def test_replay_needs_a_belief_that_recomputes_its_features():
    with pytest.raises(ValueError, match="replay_features"):
        agents.make("oracle_rh", **{"bonuses.0.train_on": "replay"}).check_task("cheetah_dir_sparse")
    with pytest.raises(ValueError, match="train_on"):
        BonusConfig(train_on="buffer")
