"""The ASOR glue of the SAC family, built in this process (no Ray started) and fed hand-made
transitions: the SAC Learner's TD targets see r + λ·b with b from the discriminator
before its step, the aux modules train once per call, V(s) is the twin critics' minimum at π's
deterministic action, the many-Learner helpers split rows as documented, and MAPLE's bonus
follows each setting (normalisation, potential shaping, padding)."""

from __future__ import annotations

import copy
import os

import gymnasium as gym
import numpy as np
import pytest
import torch
import torch.distributed as dist
from ray.rllib.algorithms.sac import SACConfig
from ray.rllib.core import DEFAULT_MODULE_ID, Columns
from ray.rllib.core.models.base import ENCODER_OUT

import rllib_asor
from rllib_asor.algorithms.sac.asor_adapter import soft_q_state_values
from rllib_asor.algorithms.sac.fast import fast_off_policy
from rllib_asor.algorithms.sac.replay import MINIBATCH_KEY, FlatTransitions
from rllib_asor.asor import trainer as trainer_module
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import ProxyInputs, make_proxy
from rllib_asor.asor.reward import potential_shaping, reward_bonus, standardize
from rllib_asor.asor.trainer import AsorTrainer
from rllib_asor.asor.update import AsorBatch, AsorResult, AsorState, asor_update
from rllib_asor.rllib import connector
from rllib_asor.rllib.learners import asor_module_id
from tests.rllib.test_glue_behaviour import policy_batches_seen

OBS = gym.spaces.Box(-10, 10, (3,), np.float32)
BOX = gym.spaces.Box(-1, 1, (2,), np.float32)
DISC = asor_module_id(DEFAULT_MODULE_ID)


def asor_trainer(learner) -> AsorTrainer:
    """The default policy's `AsorTrainer`."""
    return learner.module[DISC].unwrapped().trainer
SMALL = {"disc_hiddens": [16], "rnd_hiddens": [16], "rnd_embedding_dim": 8, "seed": 0}


def real_batch(
    features: torch.Tensor,
    next_features: torch.Tensor,
    rewards: torch.Tensor,
    terminateds: torch.Tensor,
    values: torch.Tensor,
    gamma: float,
    timestep: float,
    actions: torch.Tensor | None = None,
    dynamics_ids: torch.Tensor | None = None,
) -> AsorBatch:
    """An `AsorBatch` of real transitions (what the piece ranks for MAPLE)."""
    return AsorBatch(
        features=features,
        env_rewards=rewards,
        values=values,
        gamma=gamma,
        timestep=timestep,
        proxy_inputs=ProxyInputs(features, actions, next_features, dynamics_ids),
        next_features=next_features,
        terminateds=terminateds,
    )


def maple_asor_bonus(
    cfg: AsorConfig,
    state: AsorState,
    proxy: torch.nn.Module | None,
    real: AsorBatch,
    obs: torch.Tensor,
    next_obs: torch.Tensor,
    terminateds: torch.Tensor,
    valid: torch.Tensor,
    rng: np.random.Generator,
) -> tuple[torch.Tensor, AsorResult]:
    """What the piece does with MAPLE's adapter: ASOR's update on the real rows, then the
    bonus of every valid row of the SAC batch (`connector.bonus_on_rows`)."""
    result = asor_update(cfg, state, proxy, real, rng)
    rows = {
        Columns.OBS: obs,
        Columns.NEXT_OBS: next_obs,
        Columns.TERMINATEDS: terminateds,
        "valid": valid,
    }
    return connector.bonus_on_rows(cfg, state, result.lam, rows, real.gamma), result


def sac_learner(action_space: gym.Space = BOX, batch: int = 32, gamma: float = 0.99, **asor):
    config = (
        SACConfig()
        .environment(observation_space=OBS, action_space=action_space)
        .training(
            gamma=gamma,
            train_batch_size_per_learner=batch,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 1000},
        )
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .debugging(seed=0)
    )
    config = rllib_asor.with_asor(fast_off_policy(config), **(SMALL | asor))
    spaces = {"__env__": (OBS, action_space), DEFAULT_MODULE_ID: (OBS, action_space)}
    return config.build_learner(env=None, spaces=spaces)


def transitions(n: int = 64, seed: int = 0) -> dict[str, np.ndarray]:
    """Rows in two clusters of observations (±2), the +2 ones paying 1, the others 0."""
    rng = np.random.default_rng(seed)
    centre = np.where(np.arange(n) % 2, 2.0, -2.0)[:, None]
    obs = (rng.normal(size=(n, 3)) * 0.3 + centre).astype(np.float32)
    return {
        Columns.OBS: obs,
        Columns.NEXT_OBS: (obs + 0.1).astype(np.float32),
        Columns.ACTIONS: rng.uniform(-1, 1, (n, 2)).astype(np.float32),
        Columns.REWARDS: (np.arange(n) % 2).astype(np.float32),
        Columns.TERMINATEDS: np.zeros(n, bool),
        Columns.TRUNCATEDS: np.zeros(n, bool),
    }


def update(learner, cols, steps: int = 1000):
    return learner.update(
        episodes=[FlatTransitions(cols)], timesteps={"num_env_steps_sampled_lifetime": steps}
    )


def params(module) -> dict[str, torch.Tensor]:
    return {k: v.detach().clone() for k, v in module.state_dict().items()}


def changed(before: dict, module) -> bool:
    return any(not torch.equal(before[k], v) for k, v in module.state_dict().items())


def test_sac_td_targets_see_the_bonus_of_the_discriminator_before_its_step(monkeypatch):
    learner = sac_learner(preset="paper", lambda_=0.5)
    cols = transitions()
    disc_before = copy.deepcopy(asor_trainer(learner).state.disc)
    seen = policy_batches_seen(monkeypatch, learner)
    policy = params(learner.module[DEFAULT_MODULE_ID])
    disc = params(asor_trainer(learner).state)
    proxy = params(asor_trainer(learner).proxy)
    results = update(learner, cols)
    assert len(seen) == 2  # 64 rows in minibatches of the train batch size (32)
    env_reward = {
        tuple(o): r for o, r in zip(cols[Columns.OBS], cols[Columns.REWARDS], strict=True)
    }
    for b in seen:
        obs, rewards = b[Columns.OBS], b[Columns.REWARDS]
        with torch.no_grad():
            bonus = 0.5 * reward_bonus(disc_before(obs), "log", -5.0)
        expected = torch.tensor([env_reward[tuple(o)] for o in obs.numpy()]) + bonus
        torch.testing.assert_close(rewards, expected)
        assert (bonus < 0).all()
    assert changed(policy, learner.module[DEFAULT_MODULE_ID])
    assert results[DISC]["lambda"].peek() == pytest.approx(0.5)  # ASOR's statistics reported
    assert changed(disc, asor_trainer(learner).state)
    assert changed(proxy, asor_trainer(learner).proxy)


def escp_learner(gamma: float, **asor):
    """ESCP+ASOR's Learner in this process (its module reads windows of 4 steps)."""
    config = (
        rllib_asor.EscpConfig()
        .environment(observation_space=OBS, action_space=BOX)
        .training(
            gamma=gamma,
            train_batch_size_per_learner=32,
            replay_buffer_config={"type": "EpisodeReplayBuffer", "capacity": 1000},
        )
        .escp(history_len=4, rmdm_min_replay=0)
        .debugging(seed=0)
    )
    config = rllib_asor.with_asor(config, **(SMALL | asor))
    spaces = {"__env__": (OBS, BOX), DEFAULT_MODULE_ID: (OBS, BOX)}
    return config.build_learner(env=None, spaces=spaces)


def escp_transitions(n: int = 64) -> dict[str, np.ndarray]:
    from rllib_asor.algorithms.escp.replay import DYNAMICS_ID, NEXT_WINDOW, WINDOW

    cols = transitions(n)
    rng = np.random.default_rng(1)
    cols[WINDOW] = rng.normal(size=(n, 4, 5)).astype(np.float32)
    cols[NEXT_WINDOW] = rng.normal(size=(n, 4, 5)).astype(np.float32)
    cols[DYNAMICS_ID] = (np.arange(n) % 3).astype(np.int64)
    return cols


@pytest.mark.parametrize("algo", ["sac", "escp"])
def test_potential_shaping_uses_the_configs_gamma_and_the_critics_values(algo, monkeypatch):
    """r + λ(γ·b(s′) − b(s)) with the algorithm's γ (0.5 here), b = log ω before the step; the
    ranking's V(s) is the algorithm's own (soft-Q critics, ESCP's with z̄)."""
    settings = {"preset": "paper", "lambda_": 0.5, "shaping": "potential"}
    if algo == "sac":
        learner, cols = sac_learner(gamma=0.5, **settings), transitions()
    else:
        learner, cols = escp_learner(0.5, **settings), escp_transitions()
    module = learner.module[DEFAULT_MODULE_ID].unwrapped()
    disc_before = copy.deepcopy(asor_trainer(learner).state.disc)
    seen, ranked = policy_batches_seen(monkeypatch, learner), []
    real_update = trainer_module.asor_update

    def update_spy(cfg, state, proxy, batch, rng):
        ranked.append((batch.values.clone(), batch.ranked))
        return real_update(cfg, state, proxy, batch, rng)

    monkeypatch.setattr(trainer_module, "asor_update", update_spy)
    tensors = {k: torch.from_numpy(v) for k, v in cols.items()}
    with torch.no_grad():
        expected_values = (
            soft_q_state_values(module, tensors) if algo == "sac" else module.state_values(tensors)
        )
    update(learner, cols)
    env_reward = {
        tuple(o): r for o, r in zip(cols[Columns.OBS], cols[Columns.REWARDS], strict=True)
    }
    b = seen[0]
    with torch.no_grad():
        bonus = reward_bonus(disc_before(b[Columns.OBS]), "log", -5.0)
        next_bonus = reward_bonus(disc_before(b[Columns.NEXT_OBS]), "log", -5.0)
    env = torch.tensor([env_reward[tuple(o)] for o in b[Columns.OBS].numpy()])
    torch.testing.assert_close(b[Columns.REWARDS], env + 0.5 * (0.5 * next_bonus - bonus))
    values, rows = ranked[0]  # the fast path ranks one minibatch of the call's rows
    torch.testing.assert_close(values, expected_values if rows is None else expected_values[rows])


def rows_trained(monkeypatch) -> dict[str, int]:
    """Rows ASOR's networks train on from now on (both networks, summed over the steps)."""
    rows = {"rows": 0}
    real = AsorTrainer._minibatches

    def counted(self, n, size, budget):
        for idx in real(self, n, size, budget):
            rows["rows"] += len(idx)
            yield idx

    monkeypatch.setattr(AsorTrainer, "_minibatches", counted)
    return rows


def test_aux_modules_take_one_minibatch_per_call_unless_aux_epochs_is_set(monkeypatch):
    rows = rows_trained(monkeypatch)
    learner = sac_learner()
    update(learner, transitions(96))
    assert learner.config.learner_config_dict[MINIBATCH_KEY] == 32
    assert rows["rows"] == 2 * 32  # one minibatch each (discriminator, proxy), of 3 SAC steps
    rows["rows"] = 0
    update(learner, transitions(16))
    assert rows["rows"] == 2 * 32  # a minibatch's rows each, also from a call of fewer rows

    learner = sac_learner(aux_epochs=2)
    rows["rows"] = 0
    update(learner, transitions(96))
    assert rows["rows"] == 2 * 2 * 96  # two passes each over the call's 96 rows


def test_the_fast_path_trains_the_ensemble_proxy_on_the_ranked_rows():
    """With more rows than a minibatch only a random subset is ranked; the ensemble proxy
    still gets those rows' actions and next states, and trains on them."""
    learner = sac_learner(proxy="ensemble")
    proxy = learner.module[DISC].unwrapped().trainer.proxy
    before = params(proxy)
    update(learner, transitions(96))
    after = params(proxy)
    assert any(not torch.equal(before[k], after[k]) for k in before)


def test_soft_q_state_values_is_the_twin_minimum_at_the_squashed_mean():
    module = sac_learner().module[DEFAULT_MODULE_ID].unwrapped()
    obs = torch.randn(5, 3)
    with torch.no_grad():
        values = soft_q_state_values(module, {Columns.OBS: obs})
        logits = module.pi(module.pi_encoder({Columns.OBS: obs})[ENCODER_OUT])
        action = torch.tanh(logits.chunk(2, dim=-1)[0])
        q = module.compute_q_values({Columns.OBS: obs, Columns.ACTIONS: action})
        q1 = module._qf_forward_train_helper(
            {Columns.OBS: obs, Columns.ACTIONS: action}, module.qf_encoder, module.qf
        )
        q2 = module._qf_forward_train_helper(
            {Columns.OBS: obs, Columns.ACTIONS: action}, module.qf_twin_encoder, module.qf_twin
        )
    torch.testing.assert_close(values, q)
    torch.testing.assert_close(values, torch.minimum(q1, q2))


def test_soft_q_state_values_is_the_policy_expectation_for_discrete_actions():
    module = sac_learner(gym.spaces.Discrete(3)).module[DEFAULT_MODULE_ID].unwrapped()
    obs = torch.randn(5, 3)
    with torch.no_grad():
        values = soft_q_state_values(module, {Columns.OBS: obs})
        probs = torch.softmax(module.pi(module.pi_encoder({Columns.OBS: obs})[ENCODER_OUT]), -1)
        q_all = module.compute_q_values({Columns.OBS: obs}, squeeze=False)
    assert q_all.shape == (5, 3)
    torch.testing.assert_close(values, (probs * q_all).sum(-1))


# ------------------------------------------------------------------ several Learners
def test_rank_and_size_and_gather_in_a_one_process_group(tmp_path):
    assert connector.rank_and_size() == (0, 1)
    os.environ.setdefault("MASTER_ADDR", "127.0.0.1")
    dist.init_process_group(
        "gloo", init_method=f"file://{tmp_path / 'store'}", rank=0, world_size=1
    )
    try:
        assert connector.rank_and_size() == (0, 1)
        batch = real_batch(
            torch.ones(4, 3),
            torch.zeros(4, 3),
            torch.arange(4.0),
            torch.zeros(4, dtype=torch.bool),
            torch.full((4,), 2.0),
            gamma=0.9,
            timestep=7.0,
        )
        (got,) = connector.gather_batches(batch, "cpu")
        torch.testing.assert_close(got.features, batch.features)
        torch.testing.assert_close(got.env_rewards, batch.env_rewards)
        torch.testing.assert_close(got.proxy_inputs.next_features, batch.next_features)
        assert got.gamma == 0.9 and got.timestep == 7.0
        assert connector.gather_batches(None, "cpu") == [None]
    finally:
        dist.destroy_process_group()
    assert connector.rank_and_size() == (0, 1)


# ------------------------------------------------------------------ MAPLE's bonus
def _maple_case(seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    real = real_batch(
        torch.randn(40, 3, generator=g),
        torch.randn(40, 3, generator=g),
        torch.rand(40, generator=g),
        torch.zeros(40, dtype=torch.bool),
        torch.randn(40, generator=g),
        gamma=0.9,
        timestep=0.0,
    )
    obs = torch.randn(4, 5, 3, generator=g)
    next_obs = torch.randn(4, 5, 3, generator=g)
    terminateds = torch.zeros(4, 5, dtype=torch.bool)
    terminateds[1, 2] = True
    valid = torch.ones(4, 5, dtype=torch.bool)
    valid[3, 3:] = False
    return real, obs, next_obs, terminateds, valid


def test_maple_bonus_is_zero_without_real_states():
    cfg = AsorConfig.from_dict({**SMALL, "preset": "paper", "lambda_": 0.1})
    real, obs, next_obs, terminateds, valid = _maple_case()
    empty = real_batch(
        *(x[:0] for x in (real.features, real.next_features, real.env_rewards, real.terminateds)),
        real.values[:0],
        gamma=0.9,
        timestep=0.0,
    )
    delta, result = maple_asor_bonus(
        cfg,
        AsorState(cfg, 3),
        make_proxy(cfg, 3, 2, 0),
        empty,
        obs,
        next_obs,
        terminateds,
        valid,
        np.random.default_rng(0),
    )
    assert result.metrics == {} and torch.equal(delta, torch.zeros(4, 5))


ROBUST_FIXED = {"lambda_": 0.2, "lambda_relative": False, "lambda_warmup": False}


@pytest.mark.parametrize(
    ("settings", "norm", "potential"),
    [
        ({"preset": "paper", "lambda_": 0.1}, "off", False),
        (
            {"preset": "paper", "lambda_": 0.1, "bonus_norm": "batch", "bonus_clip": 1.5},
            "batch",
            False,
        ),
        ({**ROBUST_FIXED, "bonus_share_max": 0.0}, "batch", True),
        ({**ROBUST_FIXED, "bonus_share_max": 0.0, "bonus_norm": "running"}, "running", True),
        (ROBUST_FIXED, "batch", True),  # the cap on the bonus's share scales λ down
        ({**ROBUST_FIXED, "bonus_share_max": 0.0, "logit_clip": 0.5}, "batch", True),
        ({"preset": "paper", "lambda_": 0.1, "shaping": "potential"}, "off", True),
    ],
)
def test_maple_bonus_follows_the_settings_on_valid_steps_only(settings, norm, potential):
    cfg = AsorConfig.from_dict({**SMALL, "real_source": "batch", **settings})
    state = AsorState(cfg, 3)
    real, obs, next_obs, terminateds, valid = _maple_case()
    disc = copy.deepcopy(state.disc)
    delta, result = maple_asor_bonus(
        cfg,
        state,
        make_proxy(cfg, 3, 2, 0),
        real,
        obs,
        next_obs,
        terminateds,
        valid,
        np.random.default_rng(0),
    )
    assert delta.shape == (4, 5) and (delta[~valid] == 0).all()
    lam = result.metrics["lambda"]
    if settings.get("bonus_share_max", 0.2 if "preset" not in settings else 0.0):
        assert 0.0 < lam < settings["lambda_"]
    else:
        assert lam == pytest.approx(settings["lambda_"])
    m = valid.reshape(-1)
    with torch.no_grad():
        form = cfg.reward_form
        # the call does not train the discriminator (the Learner does, after it); its input
        # normaliser (robust) has seen this call's real states
        for name, weight in disc.named_parameters():
            torch.testing.assert_close(weight, dict(state.disc.named_parameters())[name])
        omega = state.disc
        b = reward_bonus(omega(obs.reshape(-1, 3)[m]), form, cfg.log_omega_min, cfg.logit_clip)
        nb = reward_bonus(
            omega(next_obs.reshape(-1, 3)[m]), form, cfg.log_omega_min, cfg.logit_clip
        )
    if norm == "batch":
        mean, var = b.mean(), b.var(unbiased=False)
    elif norm == "running":
        mean, var = state.bonus_rms.mean.reshape(()), state.bonus_rms.var.reshape(())
    if norm != "off":
        b, nb = (standardize(x, mean, var, cfg.bonus_clip) for x in (b, nb))
        assert b.abs().max() <= cfg.bonus_clip
    if potential:
        b = potential_shaping(b, nb, terminateds.reshape(-1)[m], 0.9)
    torch.testing.assert_close(delta.reshape(-1)[m], lam * b)


# ------------------------------------------------------------------ CQL (offline batches)
def cql_learner(**asor):
    from ray.rllib.algorithms.cql import CQLConfig

    config = (
        CQLConfig()
        .environment(observation_space=OBS, action_space=BOX)
        .training(train_batch_size_per_learner=32)
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .debugging(seed=0)
    )
    config = rllib_asor.with_asor(config, **(SMALL | asor))
    spaces = {"__env__": (OBS, BOX), DEFAULT_MODULE_ID: (OBS, BOX)}
    return config.build_learner(env=None, spaces=spaces)


def test_cql_lambda_schedule_follows_the_dataset_rows_trained_on(monkeypatch):
    from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch

    # λ is 0 until 32 rows were trained on, then 1 (paper form: b = log ω < 0)
    learner = cql_learner(preset="paper", lambda_=[[0, 0.0], [31, 0.0], [32, 1.0]])
    seen = policy_batches_seen(monkeypatch, learner)
    cols = transitions(32)
    cols["weights"] = np.ones(32, np.float32)
    cols["n_step"] = np.ones(32, np.int64)
    timesteps = {"num_env_steps_sampled_lifetime": 0}
    for _ in range(2):
        batch = MultiAgentBatch({DEFAULT_MODULE_ID: SampleBatch(dict(cols))}, env_steps=32)
        results = learner.update(batch=batch, timesteps=timesteps)
    assert results[DISC]["lambda"].peek() == pytest.approx(1.0)  # ASOR's statistics reported
    assert len(seen) == 2
    env = torch.from_numpy(cols[Columns.REWARDS])
    torch.testing.assert_close(seen[0][Columns.REWARDS], env)
    assert (seen[1][Columns.REWARDS] < env).all()
    assert learner._asor_piece.rows_ranked == 64  # λ's timestep for the next batch


# ------------------------------------------------------------------ MAPLE's Learner
def maple_learner(**asor):
    config = rllib_asor.MapleConfig().environment(observation_space=OBS, action_space=BOX)
    config = rllib_asor.with_asor(config.debugging(seed=0), **(SMALL | asor))
    spaces = {"__env__": (OBS, BOX), DEFAULT_MODULE_ID: (OBS, BOX)}
    return config.build_learner(env=None, spaces=spaces)


def maple_batch(learner, seed: int = 0, segments: int = 6, steps: int = 4, real: int = 24):
    """Hand-made MAPLE train batch: segments (the last one padded after 2 steps) and `real`
    flat real transitions with their GRUs' hidden states (the `real_*` columns)."""
    from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch

    g = torch.Generator().manual_seed(seed)
    h = learner.module[DEFAULT_MODULE_ID].unwrapped().settings.gru_hidden
    b, t = segments, steps
    valid = torch.ones(b, t, dtype=torch.bool)
    valid[-1, 2:] = False
    cols = {
        "obs": torch.randn(b, t, 3, generator=g),
        "actions": torch.rand(b, t, 2, generator=g) * 2 - 1,
        "next_obs": torch.randn(b, t, 3, generator=g),
        "last_actions": torch.rand(b, t, 2, generator=g) * 2 - 1,
        "rewards": torch.rand(b, t, generator=g),
        "terminateds": torch.zeros(b, t, dtype=torch.bool),
        "valid": valid,
        "policy_hidden": torch.randn(b, h, generator=g),
        "value_hidden": torch.randn(b, h, generator=g),
        "real_obs": torch.randn(real, 3, generator=g),
        "real_next_obs": torch.randn(real, 3, generator=g),
        "real_actions": torch.rand(real, 2, generator=g) * 2 - 1,
        "real_last_actions": torch.rand(real, 2, generator=g) * 2 - 1,
        "real_rewards": torch.rand(real, generator=g),
        "real_terminateds": torch.arange(real) % 5 == 0,
        "real_dynamics_ids": torch.arange(real) % 3,
        "real_policy_hidden": torch.randn(real, h, generator=g),
        "real_value_hidden": torch.randn(real, h, generator=g),
    }
    cols = {k: v.numpy() for k, v in cols.items()}
    return cols, MultiAgentBatch({DEFAULT_MODULE_ID: SampleBatch(cols)}, env_steps=b)


def maple_piece_spies(monkeypatch) -> tuple[list, list]:
    """Record what the ASOR piece ranks (batch, discriminator before, result) and the rows it
    gives the bonus to."""
    calls, rows = [], []
    real_update, real_bonus = trainer_module.asor_update, connector.bonus_on_rows

    def update_spy(cfg, state, proxy, batch, rng):
        calls.append((batch, copy.deepcopy(state.disc)))
        out = real_update(cfg, state, proxy, batch, rng)
        calls[-1] += (out,)
        return out

    def bonus_spy(cfg, state, lam, bonus_rows, gamma):
        rows.append(bonus_rows)
        return real_bonus(cfg, state, lam, bonus_rows, gamma)

    monkeypatch.setattr(trainer_module, "asor_update", update_spy)
    monkeypatch.setattr(connector, "bonus_on_rows", bonus_spy)
    return calls, rows


def test_maple_update_ranks_the_real_states_and_adds_the_bonus_to_every_valid_step(monkeypatch):
    from rllib_asor.algorithms.maple import learner as maple_learner_module
    from rllib_asor.algorithms.maple.losses import state_values

    learner = maple_learner(preset="paper", lambda_=0.1)
    nets = learner.module[DEFAULT_MODULE_ID].unwrapped().nets
    bonuses, aux = [], []
    calls, rows = maple_piece_spies(monkeypatch)
    real_losses = maple_learner_module.maple_losses
    real_disc, real_proxy = AsorTrainer.train_discriminator, AsorTrainer.train_proxy

    def losses_spy(nets_, b, **kw):
        bonuses.append(kw["bonus"].clone())
        return real_losses(nets_, b, **kw)

    def disc_spy(self, x, y, *args, **kw):
        aux.append({"disc_obs": x.clone(), "disc_label": y.clone()})
        return real_disc(self, x, y, *args, **kw)

    def proxy_spy(self, x, *args, **kw):
        aux[-1]["proxy_obs"] = x.features.clone()
        return real_proxy(self, x, *args, **kw)

    monkeypatch.setattr(maple_learner_module, "maple_losses", losses_spy)
    monkeypatch.setattr(AsorTrainer, "train_discriminator", disc_spy)
    monkeypatch.setattr(AsorTrainer, "train_proxy", proxy_spy)
    disc, proxy = params(asor_trainer(learner).state), params(asor_trainer(learner).proxy)
    cols, batch = maple_batch(learner)
    t = {k: torch.from_numpy(v) for k, v in cols.items()}
    expected_values = state_values(
        nets, t["real_obs"], t["real_last_actions"], t["real_policy_hidden"], t["real_value_hidden"]
    )
    results = learner.update(batch=batch, timesteps={"maple_gradient_steps": 0})
    for i in (1, 2):
        later = learner.update(batch=maple_batch(learner, seed=i)[1], timesteps={"s": i})

    real, disc_before, result = calls[0]
    torch.testing.assert_close(real.features, t["real_obs"])
    torch.testing.assert_close(real.next_features, t["real_next_obs"])
    torch.testing.assert_close(real.env_rewards, t["real_rewards"])
    assert torch.equal(real.terminateds, t["real_terminateds"])
    torch.testing.assert_close(real.proxy_inputs.features, t["real_obs"])
    torch.testing.assert_close(real.values, expected_values)
    assert real.gamma == pytest.approx(learner.config.gamma)
    # λ's timestep: the dataset rows ranked so far
    assert [c[0].timestep for c in calls] == [0.0, 24.0, 48.0]
    # each update reports its own ASOR statistics (not a mean over updates)
    assert later[DISC]["value_mean"].peek() == pytest.approx(calls[2][2].metrics["value_mean"])
    torch.testing.assert_close(rows[0][Columns.OBS], t["obs"])
    torch.testing.assert_close(rows[0][Columns.NEXT_OBS], t["next_obs"])
    assert torch.equal(rows[0]["valid"], t["valid"])
    assert torch.equal(rows[0][Columns.TERMINATEDS], t["terminateds"])

    # every valid step, real or model, gets λ·log ω from the discriminator before its step
    with torch.no_grad():
        expected = 0.1 * reward_bonus(disc_before(t["obs"].reshape(-1, 3)), "log", -5.0)
    expected = expected.reshape(6, 4) * t["valid"]
    torch.testing.assert_close(bonuses[0], expected)
    assert (bonuses[0][t["valid"]] < 0).all()
    # the discriminator and the proxy train on the real states' partition, in the same update
    torch.testing.assert_close(aux[0]["disc_obs"], result.disc_features)
    torch.testing.assert_close(aux[0]["disc_label"], result.disc_labels)
    torch.testing.assert_close(aux[0]["proxy_obs"], t["real_obs"])
    assert changed(disc, asor_trainer(learner).state)
    assert changed(proxy, asor_trainer(learner).proxy)
    assert results[DISC]["lambda"].peek() == pytest.approx(0.1)


@pytest.mark.parametrize("proxy", ["ensemble", "rnd_per_dynamics"])
def test_maple_proxy_gets_the_real_actions_next_states_and_dynamics_ids(monkeypatch, proxy):
    learner = maple_learner(preset="paper", lambda_=0.1, proxy=proxy)
    calls, _ = maple_piece_spies(monkeypatch)
    cols, batch = maple_batch(learner)
    learner.update(batch=batch, timesteps={"maple_gradient_steps": 0})
    inputs = calls[0][0].proxy_inputs
    t = {k: torch.from_numpy(v) for k, v in cols.items()}
    torch.testing.assert_close(inputs.features, t["real_obs"])
    if proxy == "ensemble":
        torch.testing.assert_close(inputs.actions, t["real_actions"])
        torch.testing.assert_close(inputs.next_features, t["real_next_obs"])
    else:
        assert torch.equal(inputs.dynamics_ids, t["real_dynamics_ids"])


def test_maple_asor_partition_follows_the_asor_seed(monkeypatch):
    """`mode: random` draws D_P from the Learner's generator, seeded by `asor.seed`."""
    calls, _ = maple_piece_spies(monkeypatch)
    for seed in (0, 0, 1):
        learner = maple_learner(preset="paper", mode="random", lambda_=0.1, seed=seed)
        learner.update(batch=maple_batch(learner)[1], timesteps={"maple_gradient_steps": 0})
    labels = [c[2].disc_labels for c in calls]
    assert torch.equal(labels[0], labels[1]) and not torch.equal(labels[0], labels[2])


def test_maple_srpo_mode_trains_without_a_proxy():
    learner = maple_learner(preset="paper", mode="srpo", lambda_=0.1)
    assert asor_trainer(learner).proxy is None
    disc = params(asor_trainer(learner).state)
    results = learner.update(batch=maple_batch(learner)[1], timesteps={"maple_gradient_steps": 0})
    assert changed(disc, asor_trainer(learner).state) and "rnd_loss" not in results[DISC]


def test_the_fast_path_ranks_one_minibatch_and_gives_every_row_the_bonus(monkeypatch):
    """The discriminator trains on one minibatch per call, so only that many rows are ranked
    (V(s), counts, D_P); the bonus goes to every row of the call."""
    from rllib_asor.algorithms.sac.asor_adapter import SACAsorAdapter

    learner = sac_learner(preset="paper", lambda_=0.5)
    valued, ranked = [], []
    real_values, real_update = SACAsorAdapter.state_values, trainer_module.asor_update

    def values_spy(self, module, batch):
        valued.append(len(batch[Columns.OBS]))
        return real_values(self, module, batch)

    def update_spy(cfg, state, proxy, batch, rng):
        ranked.append(batch)
        return real_update(cfg, state, proxy, batch, rng)

    monkeypatch.setattr(SACAsorAdapter, "state_values", values_spy)
    monkeypatch.setattr(trainer_module, "asor_update", update_spy)
    seen = policy_batches_seen(monkeypatch, learner)
    cols = transitions(96)
    update(learner, cols)
    assert valued == [32]  # one minibatch of the call's 3
    (batch,) = ranked
    assert batch.features.shape[0] == 96 and batch.values.shape == (32,)
    assert batch.ranked.shape == (32,) and len(set(batch.ranked.tolist())) == 32
    env_reward = {tuple(o): r for o, r in zip(cols[Columns.OBS], cols[Columns.REWARDS], strict=True)}
    for b in seen:  # every row's reward moved (log ω < 0 in the paper's form)
        env = torch.tensor([env_reward[tuple(o)] for o in b[Columns.OBS].numpy()])
        assert (b[Columns.REWARDS] < env).all()
