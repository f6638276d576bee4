"""Unit tests of the agent components against hand computations."""

import dataclasses
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from hyperstate import agents
from hyperstate.agents.beliefs import RecurrentBelief, Trajectories, Transition, VariBADBelief, gaussian_kl
from hyperstate.agents.bonuses import BonusInput, EnsembleRND, InputSelector
from hyperstate.agents.config import BonusConfig, PPOConfig, RecurrentConfig, VAEConfig, apply_overrides
from hyperstate.agents.normalization import ReturnScaler, RunningMeanStd
from hyperstate.agents.ppo import ActorCritic, compute_gae


# Normalisation -------------------------------------------------------------------------------------
def test_running_mean_std_matches_numpy_over_batches():
    rng = np.random.default_rng(0)
    data = rng.normal(3.0, 2.0, (1000, 3))
    stats = RunningMeanStd((3,), epsilon=0.0)
    for chunk in np.array_split(data, 7):
        stats.update(chunk)
    np.testing.assert_allclose(stats.mean, data.mean(0), rtol=1e-10)
    np.testing.assert_allclose(stats.var, data.var(0), rtol=1e-10)
    np.testing.assert_allclose(stats.normalize(data).mean(0), 0.0, atol=1e-8)


def test_return_scaler_divides_by_std_of_discounted_returns():
    rewards = np.array([[1.0, 2.0], [0.0, 1.0], [3.0, 0.0]])
    lasts = np.array([[False, False], [True, False], [False, False]])
    scaler = ReturnScaler(2, gamma=0.5)
    scaler.stats = RunningMeanStd(epsilon=0.0)
    out = scaler.scale(rewards, lasts)
    # Hand-computed discounted returns, reset after `last`: env0 1, 0.5, 3; env1 2, 2, 1.
    returns = np.array([1.0, 2.0, 0.5, 2.0, 3.0, 1.0])
    np.testing.assert_allclose(out, rewards / np.sqrt(returns.var() + 1e-8))
    np.testing.assert_allclose(scaler.returns, [3.0, 1.0])


# GAE -----------------------------------------------------------------------------------------------
def test_gae_matches_hand_computation_with_truncation():
    gamma, lam = 0.9, 0.8
    rewards = np.array([[1.0], [2.0], [3.0]])
    values = np.array([[0.5], [1.0], [1.5]])
    # Step 1 ends a truncated episode whose final observation is worth 4; V(s_3) = 2.
    next_values = np.array([[1.0], [4.0], [2.0]])
    lasts = np.array([[0.0], [1.0], [0.0]])
    bootstrap = np.ones((3, 1))
    adv, ret = compute_gae(rewards, values, next_values, lasts, bootstrap, gamma, lam)
    d2 = 3.0 + gamma * 2.0 - 1.5
    d1 = 2.0 + gamma * 4.0 - 1.0  # bootstraps from the final observation, then the recursion restarts
    d0 = 1.0 + gamma * 1.0 - 0.5
    want = np.array([[d0 + gamma * lam * d1], [d1], [d2]])
    np.testing.assert_allclose(adv, want)
    np.testing.assert_allclose(ret, want + values)
    # A termination (bootstrap 0) drops the final value.
    adv_term, _ = compute_gae(rewards, values, next_values, lasts, np.array([[1.0], [0.0], [1.0]]), gamma, lam)
    assert adv_term[1, 0] == pytest.approx(2.0 - 1.0)


# RND and eq. (8)-(9) --------------------------------------------------------------------------------
def _batch(next_state: torch.Tensor, next_features: torch.Tensor | None = None) -> BonusInput:
    m = next_state.shape[0]
    feats = torch.zeros(m, 0) if next_features is None else next_features
    return BonusInput(torch.zeros(m, 1), torch.zeros(m, 1), torch.zeros(m, 1), next_state, feats, feats)


def test_rnd_bonus_falls_on_repeated_inputs_and_stays_high_on_novel_ones():
    torch.manual_seed(0)
    config = BonusConfig(input="state", lr=1e-3, updates_per_iteration=50, batch_size=64, buffer_size=2000)
    rnd = EnsembleRND(InputSelector("state", [0], 0), config, torch.Generator().manual_seed(0), "rnd")
    seen = _batch(torch.linspace(-1, 1, 200)[:, None])
    novel = _batch(torch.linspace(4, 6, 200)[:, None])
    rnd.input_stats.update(np.linspace(-6, 6, 1000)[:, None])  # fixed normalisation for the comparison
    before_seen = rnd.errors(rnd.normalize(seen.next_state)).mean().item()
    before_novel = rnd.errors(rnd.normalize(novel.next_state)).mean().item()
    stats = rnd.input_stats.state_dict()
    for _ in range(6):
        rnd.update(seen)
    rnd.input_stats.load_state_dict(stats)
    after_seen = rnd.errors(rnd.normalize(seen.next_state)).mean().item()
    after_novel = rnd.errors(rnd.normalize(novel.next_state)).mean().item()
    assert after_seen < 0.1 * before_seen
    assert after_novel > 5 * after_seen
    assert after_novel > 0.3 * before_novel


def test_ensemble_uncertainty_matches_eq_9_by_hand():
    errors = torch.tensor([[1.0, 0.2, 0.0], [3.0, 0.2, 0.0], [2.0, 0.2, 0.0]])  # B=3 members, 3 inputs
    got = EnsembleRND.uncertainty(errors, beta=2.0, aleatoric=0.5)
    # mean 2, var (1+1+0)/3; mean 0.2, var 0; mean 0 → clipped at 0
    want = torch.tensor([2.0 + 2.0 * 2.0 / 3.0 - 0.5, 0.0, 0.0])
    torch.testing.assert_close(got, want)
    got_b1 = EnsembleRND.uncertainty(errors[:1], beta=2.0, aleatoric=0.0)
    torch.testing.assert_close(got_b1, errors[0])


def test_ensemble_rnd_reward_is_eq_9_of_member_errors():
    torch.manual_seed(1)
    config = BonusConfig(kind="ensemble_rnd", input="hyperstate", ensemble_size=4, beta=0.5, aleatoric=0.1)
    rnd = EnsembleRND(InputSelector("hyperstate", [1], 2), config, torch.Generator().manual_seed(0), "e")
    state = torch.randn(32, 3)
    belief = torch.softmax(torch.randn(32, 2), -1)
    bonus = rnd.reward(_batch(state, belief))
    x = rnd.normalize(torch.cat([state[:, 1:2], belief], -1))
    e = torch.stack([(g(x) - f(x)).pow(2).mean(-1) for f, g in zip(rnd.priors, rnd.predictors, strict=True)])
    want = torch.clamp(e.mean(0) + 0.5 * e.var(0, unbiased=False) - 0.1, min=0)
    torch.testing.assert_close(bonus, want)
    assert bonus.shape == (32,)


def test_input_selector_picks_state_columns_and_belief():
    batch = _batch(torch.arange(12.0).reshape(4, 3), torch.ones(4, 2))
    torch.testing.assert_close(InputSelector("state", [2], 2)(batch), torch.tensor([[2.0], [5.0], [8.0], [11.0]]))
    assert InputSelector("hyperstate", [0, 2], 2)(batch).shape == (4, 4)
    assert InputSelector("belief", [0], 2)(batch).tolist() == [[1.0, 1.0]] * 4
    with pytest.raises(ValueError, match="needs a belief"):
        InputSelector("hyperstate", [0], 0)


# Beliefs -------------------------------------------------------------------------------------------
def test_gaussian_kl_against_closed_form():
    mq, lq, mp, lp = torch.tensor([[1.0]]), torch.tensor([[0.0]]), torch.tensor([[0.0]]), torch.tensor([[np.log(4.0)]])
    # KL(N(1,1) || N(0,4)) = log(2) + (1 + 1)/8 - 1/2
    assert gaussian_kl(mq, lq, mp, lp).item() == pytest.approx(np.log(2) + 2 / 8 - 0.5, rel=1e-6)


def _toy_trajectories(b=12, t=20, seed=0):
    """Reward = task sign × state: a task a VAE can infer from a few transitions."""
    g = torch.Generator().manual_seed(seed)
    states = torch.randn(b, t + 1, 3, generator=g)
    actions = torch.randn(b, t, 2, generator=g)
    task = torch.where(torch.rand(b, generator=g) < 0.5, -1.0, 1.0)
    rewards = (task[:, None] * states[:, 1:, 0])[..., None]
    return Trajectories(states, actions, rewards, task[:, None])


def test_vae_elbo_decreases_on_fixed_batch():
    torch.manual_seed(0)
    config = VAEConfig(subsample_elbos=0, subsample_decodes=0, lr=3e-3)
    vae = VariBADBelief(3, 2, config, torch.Generator().manual_seed(0))
    batch = _toy_trajectories()
    first = vae.train_step(batch)["vae/loss"]
    for _ in range(150):
        last = vae.train_step(batch)["vae/loss"]
    assert last < 0.3 * first


def test_vae_online_posterior_equals_sequence_posterior():
    torch.manual_seed(0)
    vae = VariBADBelief(3, 2, VAEConfig(), torch.Generator().manual_seed(0))
    batch = _toy_trajectories(b=4, t=6)
    mean, logvar = vae.encoder.sequence(batch.actions, batch.rewards, batch.states[:, 1:])
    state = vae.initial_state(4, {})
    torch.testing.assert_close(vae.features(state), torch.zeros(4, 10))  # N(0, I) prior
    for t in range(6):
        state = vae.update(state, Transition(batch.actions[:, t], batch.rewards[:, t], batch.states[:, t + 1], {}))
        torch.testing.assert_close(vae.features(state), torch.cat([mean[:, t + 1], logvar[:, t + 1]], -1))


def test_recurrent_sequence_features_equal_online_features_across_resets():
    torch.manual_seed(0)
    rl2 = RecurrentBelief(3, 2, RecurrentConfig(hidden=8))
    t_len, n = 7, 3
    next_state, actions, rewards = torch.randn(t_len, n, 3), torch.randn(t_len, n, 2), torch.randn(t_len, n)
    starts = torch.zeros(t_len, n, dtype=torch.bool)
    starts[4] = True  # a new BAMDP episode begins at step 4
    h0 = torch.randn(n, 8)
    online, h = [], h0
    for t in range(t_len):
        if starts[t, 0]:
            h = rl2.reset_where(h, starts[t], {})
        online.append(rl2.features(h))
        h = rl2.update(h, Transition(actions[t], rewards[t, :, None], next_state[t], {}))
    rollout = SimpleNamespace(belief_state0=h0, next_state=next_state, actions=actions, rewards=rewards, starts=starts)
    recomputed = rl2.sequence_features(rollout, torch.tensor([2, 0]))
    torch.testing.assert_close(recomputed, torch.stack(online)[:, [2, 0]])
    assert recomputed.requires_grad


# Configs -------------------------------------------------------------------------------------------
def test_overrides_map_onto_dataclasses_and_reject_unknown_fields():
    config = apply_overrides(agents.get_preset("hyperx"), {"ppo.lr": 1e-3, "bonuses.1.weight": 3, "vae": {"lr": 5e-4}})
    assert config.ppo.lr == 1e-3 and config.vae.lr == 5e-4
    assert config.bonuses[1].weight == 3.0 and config.bonuses[0].weight == 10.0
    assert dataclasses.is_dataclass(config) and config.belief == "varibad"
    with pytest.raises(ValueError, match=r"unknown config field 'ppo.lrr' \(did you mean ppo.lr\?\)"):
        apply_overrides(config, {"ppo.lrr": 1.0})
    with pytest.raises(ValueError, match="unknown config field 'beleif'"):
        agents.make("oracle", beleif="varibad")
    with pytest.raises(ValueError, match="ppo.num_envs must be int"):
        agents.make("oracle", **{"ppo.num_envs": "8"})
    with pytest.raises(ValueError, match="bonus index"):
        apply_overrides(config, {"bonuses.5.weight": 1.0})
    with pytest.raises(ValueError, match="unknown agent preset 'hyperz'.*hyperx"):
        agents.make("hyperz")


def test_presets_cover_figure_2():
    want = {"ppo", "rl2", "oracle", "oracle_rh", "oracle_rs", "varibad", "varibad_rh", "hyperx", "oracle_ensemble_rh"}
    assert want <= set(agents.list_presets())
    hyperx = agents.get_preset("hyperx")
    assert [b.input for b in hyperx.bonuses] == ["hyperstate", "state"]
    assert [b.weight for b in hyperx.bonuses] == [10.0, 10.0]
    assert agents.get_preset("oracle_ensemble_rh").bonuses[0].ensemble_size > 1


# Reward combination, eq. (4) ------------------------------------------------------------------------
def test_combine_rewards_normalises_each_stream_weights_and_anneals():
    from hyperstate.agents.trainer import combine_rewards

    rng = np.random.default_rng(0)
    extrinsic, b1, b2 = rng.normal(0, 30, (5, 3)), rng.random((5, 3)), 100 * rng.random((5, 3))
    lasts = np.zeros((5, 3), bool)
    scalers = [ReturnScaler(3, 0.9) for _ in range(3)]
    reward, scaled = combine_rewards(
        extrinsic,
        [b1, b2],
        weights=[10.0, 2.0],
        anneal=0.25,
        lasts=lasts,
        ext_scaler=scalers[0],
        bonus_scalers=scalers[1:],
        reward_clip=1.0,
    )

    def by_hand(r):
        returns, acc = [], np.zeros(3)
        for t in range(5):
            acc = 0.9 * acc + r[t]
            returns.append(acc.copy())
        return r / np.sqrt(np.var(returns) * 5 * 3 / (5 * 3 + 1e-4) + 1e-8)

    ext = np.clip(by_hand(extrinsic), -1.0, 1.0)
    np.testing.assert_allclose(scaled[0], by_hand(b1), rtol=1e-3)
    np.testing.assert_allclose(scaled[1], by_hand(b2), rtol=1e-3)
    np.testing.assert_allclose(reward, ext + 0.25 * (10.0 * scaled[0] + 2.0 * scaled[1]), rtol=1e-3)
    assert np.abs(ext).max() == 1.0  # extrinsic clipped
    # Scale-free: a bonus 100x larger contributes the same after normalisation.
    assert np.abs(scaled[1]).mean() < 10 * np.abs(scaled[0]).mean()


def test_vae_error_bonus_is_the_reward_decoders_squared_error():
    from hyperstate.agents.bonuses import VAEErrorBonus

    torch.manual_seed(0)
    gen = torch.Generator().manual_seed(7)
    vae = VariBADBelief(3, 2, VAEConfig(), gen)
    bonus = VAEErrorBonus(vae, "vae_error")
    m = 16
    features = torch.cat([torch.randn(m, 5), torch.full((m, 5), -2.0)], -1)
    state, action, next_state, reward = torch.randn(m, 3), torch.randn(m, 2), torch.randn(m, 3), torch.randn(m, 1)
    batch = BonusInput(state, action, reward, next_state, features, features)
    before = gen.get_state()
    got = bonus.reward(batch)
    gen.set_state(before)
    z = features[:, :5] + torch.randn(m, 5, generator=gen) * torch.exp(0.5 * features[:, 5:])
    want = (vae.decoder(torch.cat([z, state, action, next_state], -1))[:, :1] - reward).pow(2)[:, 0]
    torch.testing.assert_close(got, want.detach())
    with pytest.raises(ValueError, match="varibad"):
        VAEErrorBonus(RecurrentBelief(3, 2, RecurrentConfig()), "x")


def test_feature_embed_gain_makes_the_belief_embedding_orthogonal_times_the_gain():
    torch.manual_seed(0)
    default = ActorCritic(7, 2, 3, PPOConfig(network="cleanrl"))
    after_default = torch.randn(3)
    torch.manual_seed(0)
    scaled = ActorCritic(7, 2, 3, PPOConfig(network="cleanrl", feature_embed_gain=3.0))
    # Only the belief-features embedding differs: every other layer, and what is drawn after, is the same.
    assert torch.equal(torch.randn(3), after_default)
    for (name, a), (_, b) in zip(default.named_parameters(), scaled.named_parameters(), strict=True):
        assert torch.equal(a, b) != (".features." in name), name
    for net in (scaled.actor, scaled.critic):
        linear = net["features"].net[0]
        # 32 x 2 weights with orthogonal columns of norm 3: W^T W = 9 I; no biases.
        torch.testing.assert_close(linear.weight.T @ linear.weight, 9.0 * torch.eye(2), atol=1e-5, rtol=0)
        assert not linear.bias.any()
        # The state embedding keeps PyTorch's default: weights within 1/sqrt(inputs), biases drawn too.
        state = net["state"].net[0]
        assert state.weight.abs().max() <= 7**-0.5 and state.bias.any()
    for net in (default.actor, default.critic):
        linear = net["features"].net[0]
        assert linear.weight.abs().max() <= 2**-0.5 and linear.bias.any()
    with pytest.raises(ValueError, match="feature_embed_gain"):
        PPOConfig(feature_embed_gain=0.0)


def test_reference_network_is_the_reference_codes_actor_critic():
    torch.manual_seed(0)
    model = ActorCritic(7, 2, 3, PPOConfig(network="reference"), value_heads=2)
    actor, critic = model.actor, model.critic
    # One tanh embedding per input, shared by actor and critic (the same parameters, counted once).
    assert actor["state"] is critic["state"] and actor["features"] is critic["features"]
    for embed in (actor["state"], actor["features"]):
        assert isinstance(embed.net[1], torch.nn.Tanh) and embed.net[0].bias.any()  # PyTorch's default init
    assert isinstance(actor["body"][1], torch.nn.Tanh)
    n_params = sum(p.numel() for p in model.parameters())
    own = sum(p.numel() for net in (actor, critic) for p in net["body"].parameters())
    embeddings = sum(p.numel() for e in (actor["state"], actor["features"]) for p in e.parameters())
    assert n_params == own + embeddings + 3  # + log_std
    # normc: hidden rows of norm 5/3 (tanh's gain), the mean head's rows of norm 1, zero biases ...
    linears = [m for m in actor["body"] if isinstance(m, torch.nn.Linear)]
    for linear, norm in zip(linears, [5 / 3, 5 / 3, 1.0], strict=True):
        torch.testing.assert_close(linear.weight.norm(dim=1), torch.full((linear.out_features,), norm))
        assert not linear.bias.any()
    # ... and the critic's head at PyTorch's default (uniform within 1/sqrt(128), biases drawn).
    head = [m for m in critic["body"] if isinstance(m, torch.nn.Linear)][-1]
    assert head.weight.abs().max() <= 128**-0.5 and head.bias.any() and head.out_features == 2
    # The first policy acts at full scale, and differently for the two beliefs; the cleanrl network's first
    # policy is near zero everywhere (mean head x0.01).
    state = torch.randn(256, 7)
    forward, backward = (model.mean_std(state, torch.tensor([b] * 256))[0] for b in ([0.0, 1.0], [1.0, 0.0]))
    cleanrl = ActorCritic(7, 2, 3, PPOConfig(network="cleanrl"))
    cleanrl_mean = cleanrl.mean_std(state, torch.tensor([[0.0, 1.0]] * 256))[0]
    assert forward.abs().mean() > 0.1 and (forward - backward).abs().mean() > 0.02
    assert cleanrl_mean.abs().mean() < 0.02
    with pytest.raises(ValueError, match="ppo.network"):
        PPOConfig(network="resnet")


def test_reference_network_saves_and_loads_with_its_embeddings_still_shared(tmp_path):
    torch.manual_seed(0)
    model = ActorCritic(7, 2, 3, PPOConfig(network="reference"))
    torch.save(model.state_dict(), tmp_path / "model.pt")
    torch.manual_seed(1)
    other = ActorCritic(7, 2, 3, PPOConfig(network="reference"))
    other.load_state_dict(torch.load(tmp_path / "model.pt"))
    assert other.actor["state"] is other.critic["state"]
    for a, b in zip(model.parameters(), other.parameters(), strict=True):
        assert torch.equal(a, b)


# The per-step fast path ------------------------------------------------------------------------------
@pytest.mark.parametrize("embed,network", [(32, "cleanrl"), (0, "cleanrl"), (32, "reference")])
def test_actor_critic_step_equals_mean_std_and_value_exactly_through_training(embed, network):
    # `step` runs the layers as plain functions over the modules' own parameters: it must give the very
    # numbers of the module calls, and keep doing so after optimiser steps and load_state_dict.
    torch.manual_seed(0)
    model = ActorCritic(7, 4, 3, dataclasses.replace(PPOConfig(), embed=embed, network=network))
    state, features = torch.randn(16, 7), torch.randn(16, 4)

    def check():
        mean, std, value = model.step(state, features)
        expected_mean, expected_std = model.mean_std(state, features)
        assert torch.equal(mean, expected_mean) and torch.equal(std, expected_std)
        assert torch.equal(value, model.value(state, features))
        assert value.shape == (16, 1) and mean.shape == (16, 3)  # one value head

    check()
    optimizer = torch.optim.Adam(model.parameters(), lr=1e-2)
    for _ in range(3):
        mean, _ = model.mean_std(state, features)
        (mean.square().sum() + model.value(state, features).square().sum()).backward()
        optimizer.step()
        optimizer.zero_grad()
    check()
    other = ActorCritic(7, 4, 3, dataclasses.replace(PPOConfig(), embed=embed, network=network))
    model.load_state_dict(other.state_dict())
    check()
    assert torch.equal(model.step(state, features)[0], other.mean_std(state, features)[0])


def test_vae_encoder_step_equals_the_gru_module_exactly():
    torch.manual_seed(0)
    encoder = VariBADBelief(3, 2, VAEConfig(), torch.Generator().manual_seed(0)).encoder
    h = torch.randn(16, encoder.hidden)
    action, reward, next_state = torch.randn(16, 2), torch.randn(16, 1), torch.randn(16, 3)
    out, expected_h = encoder.gru(encoder.embed(action, reward, next_state)[None], h[None])
    expected_mean, expected_logvar = encoder.head(out[0]).chunk(2, dim=-1)
    new_h, mean, logvar = encoder.step(h, action, reward, next_state)
    assert torch.equal(new_h, expected_h[0])
    assert torch.equal(mean, expected_mean) and torch.equal(logvar, expected_logvar)
