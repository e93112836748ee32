"""The ASOR ↔ RLlib glue on a real PPO Learner built in this process (no Ray started), fed
hand-made episodes: the discriminator is trained in the Learner's update, the archive
is filled in the update that ends the episodes, the rewards GAE sees are r + λ·b, every piece of
ASOR state survives the Learner's checkpoint (auto-λ among the cases), ASOR's networks train
their passes outside the policy's minibatches, which are those of PPO without ASOR."""

from __future__ import annotations

import copy

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.connectors.common import AddObservationsFromEpisodesToBatch
from ray.rllib.core import DEFAULT_MODULE_ID, Columns
from ray.rllib.core.rl_module.apis import ValueFunctionAPI
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.core.rl_module.torch import TorchRLModule
from ray.rllib.env.multi_agent_episode import MultiAgentEpisode
from ray.rllib.env.single_agent_episode import SingleAgentEpisode
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME
from ray.rllib.utils.metrics.metrics_logger import MetricsLogger

import rllib_asor
from rllib_asor.algorithms.common.asor_adapter import DYNAMICS_ID
from rllib_asor.asor.reward import reward_bonus
from rllib_asor.asor.trainer import AsorTrainer
from rllib_asor.rllib.callbacks import lift_asor_metrics
from rllib_asor.rllib.connector import AddDynamicsIdsToBatch, AsorRewardConnector, SharedValuesGAE
from rllib_asor.rllib.learners import asor_module_id, is_aux_module
from tests.asor.test_state_behaviour import pieces

pytestmark = pytest.mark.heavy  # starts Ray or a subprocess: scheduled first (conftest)

OBS = gym.spaces.Box(-10, 10, (3,), np.float32)
ACT = gym.spaces.Discrete(2)
DISC = asor_module_id(DEFAULT_MODULE_ID)
SMALL = {"disc_hiddens": [16], "rnd_hiddens": [16], "rnd_embedding_dim": 8, "seed": 0}


def learner(policies_to_train=None, **asor):
    config = (
        PPOConfig()
        .environment(observation_space=OBS, action_space=ACT)
        .training(train_batch_size=60, minibatch_size=30, num_epochs=2, lr=1e-3)
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .debugging(seed=0)
    )
    if policies_to_train is not None:  # a single-agent config may name its policy
        config.multi_agent(policies_to_train=policies_to_train)
    config = rllib_asor.with_asor(config, **(SMALL | asor))
    spaces = {"__env__": (OBS, ACT), DEFAULT_MODULE_ID: (OBS, ACT)}
    return config.build_learner(env=None, spaces=spaces)


def episodes(seed: int, n: int = 6, length: int = 10, terminated: bool = True, ids: bool = True):
    """Paying episodes (odd) in the +2 cluster of observations, the others in the −2 cluster."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        centre = 2.0 if i % 2 else -2.0
        obs = lambda c=centre: (rng.normal(size=3) * 0.3 + c).astype(np.float32)  # noqa: E731
        ep = SingleAgentEpisode(observation_space=OBS, action_space=ACT)
        info = {"dynamics_id": i % 3} if ids else {}
        ep.add_env_reset(observation=obs(), infos=info)
        for t in range(length):
            last = t == length - 1
            ep.add_env_step(
                observation=obs(),
                action=int(rng.integers(2)),
                reward=(1.0 if i % 2 else 0.0) if last else -0.02,
                infos=info,
                terminated=terminated and last,
                extra_model_outputs={
                    Columns.ACTION_LOGP: np.float32(-0.69),
                    Columns.ACTION_DIST_INPUTS: np.zeros(2, np.float32),
                },
            )
        out.append(ep.to_numpy())
    return out


def ma_learner(**asor):
    """Multi-agent PPO+ASOR: agent "a<i>" acts for policy "p<i>" (i = 0, 1)."""
    config = (
        PPOConfig()
        .environment(observation_space=OBS, action_space=ACT)
        .multi_agent(policies={"p0", "p1"}, policy_mapping_fn=lambda aid, *a, **k: f"p{aid[-1]}")
        .training(train_batch_size=60, minibatch_size=30, num_epochs=2, lr=1e-3)
        .rl_module(model_config={"fcnet_hiddens": [16]})
        .debugging(seed=0)
    )
    config = rllib_asor.with_asor(config, **(SMALL | asor))
    spaces = {"__env__": (OBS, ACT), "p0": (OBS, ACT), "p1": (OBS, ACT)}
    return config.build_learner(env=None, spaces=spaces)


def ma_episodes(seed: int, agents: tuple[str, ...], n: int = 4, length: int = 10):
    """Like `episodes`, with `agents` acting together (each for its own policy)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        centre = 2.0 if i % 2 else -2.0

        def obs(c=centre):
            return {a: (rng.normal(size=3) * 0.3 + c).astype(np.float32) for a in agents}

        ep = MultiAgentEpisode(
            observation_space=dict.fromkeys(agents, OBS),
            action_space=dict.fromkeys(agents, ACT),
            agent_to_module_mapping_fn=lambda aid, episode: f"p{aid[-1]}",
        )
        ep.add_env_reset(observations=obs(), infos={a: {} for a in agents})
        outputs = {Columns.ACTION_LOGP: np.float32(-0.69), Columns.ACTION_DIST_INPUTS: np.zeros(2)}
        for t in range(length):
            last = t == length - 1
            ep.add_env_step(
                observations=obs(),
                actions={a: int(rng.integers(2)) for a in agents},
                rewards=dict.fromkeys(agents, (1.0 if i % 2 else 0.0) if last else -0.02),
                infos={a: {} for a in agents},
                terminateds={"__all__": last},
                truncateds={"__all__": False},
                extra_model_outputs=dict.fromkeys(agents, outputs),
            )
        out.append(ep.to_numpy())
    return out


def update(lrn, eps, step=60, minibatch_size=30):
    return lrn.update(
        episodes=eps,
        timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: step},
        minibatch_size=minibatch_size,
        num_epochs=2,
    )


def policy_batches_seen(monkeypatch, learner) -> list[dict[str, torch.Tensor]]:
    """Record what the policy's loss gets: OBS, NEXT_OBS (when there) and REWARDS per call."""
    seen: list[dict[str, torch.Tensor]] = []
    real = type(learner).compute_loss_for_module

    def spy(self, *, module_id, config, batch, fwd_out):
        if module_id == DEFAULT_MODULE_ID:
            keys = (Columns.OBS, Columns.NEXT_OBS, Columns.REWARDS)
            seen.append({k: batch[k].clone() for k in keys if k in batch})
        return real(self, module_id=module_id, config=config, batch=batch, fwd_out=fwd_out)

    monkeypatch.setattr(type(learner), "compute_loss_for_module", spy)
    return seen


def trainer(lrn, policy: str = DEFAULT_MODULE_ID) -> AsorTrainer:
    """The policy's `AsorTrainer` in the Learner's ASOR module."""
    return lrn.module[asor_module_id(policy)].unwrapped().trainer


def rows_trained(monkeypatch) -> dict[str, int]:
    """Rows each ASOR network trains on (summed over the steps), recorded from now on."""
    rows = {"disc": 0, "proxy": 0}
    for name, method in (("disc", "train_discriminator"), ("proxy", "train_proxy")):
        real = getattr(AsorTrainer, method)

        def spy(self, x, *args, _real=real, _name=name, **kwargs):
            real_batches = AsorTrainer._minibatches

            def counted(self_, n, size, budget):
                for idx in real_batches(self_, n, size, budget):
                    rows[_name] += len(idx)
                    yield idx

            monkeypatch.setattr(AsorTrainer, "_minibatches", counted)
            try:
                return _real(self, x, *args, **kwargs)
            finally:
                monkeypatch.setattr(AsorTrainer, "_minibatches", real_batches)

        monkeypatch.setattr(AsorTrainer, method, spy)
    return rows


def module_batch(lrn, eps):
    """What the Learner connector gives the loss (rewards after ASOR, before GAE's columns)."""
    return lrn._learner_connector(rl_module=lrn.module, batch={}, episodes=eps, metrics=lrn.metrics)


# ------------------------------------------------------------------ training
@pytest.mark.parametrize("policies_to_train", [None, [DEFAULT_MODULE_ID]])
def test_the_learners_update_trains_the_discriminator_and_fills_the_archive(policies_to_train):
    lrn = learner(policies_to_train, mode="srpo", lambda_warmup=False, disc_lr=1e-2)
    disc = trainer(lrn)
    before = {k: v.clone() for k, v in disc.state.disc.net.state_dict().items()}
    policy_before = {k: v.clone() for k, v in lrn.module[DEFAULT_MODULE_ID].state_dict().items()}
    results = update(lrn, episodes(0))
    # the episodes ended in this update: their 60 states are archived (3 dynamics buckets)
    assert disc.state.archive.bucket_sizes()[:3] == [20, 20, 20]
    assert disc.state.archive.open_episodes == 0
    after = disc.state.disc.net.state_dict()
    assert all(not torch.equal(after[k], before[k]) for k in before)
    assert any(
        not torch.equal(v, policy_before[k])
        for k, v in lrn.module[DEFAULT_MODULE_ID].state_dict().items()
    )
    accs = []
    for i in range(1, 15):
        results = update(lrn, episodes(i), step=60 * (i + 1))
        lifted = lift_asor_metrics(_flat(results))
        accs.append(lifted["disc_acc"])
    assert lifted["archive_states"] > 60 and lifted["real_fraction"] > 0
    assert {"disc_loss", "js_estimate", "lambda", "aug_reward_mean", "disc_grad_penalty"} <= set(
        lifted
    )
    # The real set (the best archived states) is the +2 cluster: ω separates it.
    with torch.no_grad():
        good = torch.as_tensor(np.stack([e.get_observations(0) for e in episodes(99)[1::2]]))
        bad = torch.as_tensor(np.stack([e.get_observations(0) for e in episodes(99)[0::2]]))
        assert disc.state.disc(good).mean() > disc.state.disc(bad).mean()
    assert accs[-1] > accs[0] or accs[0] > 0.9


def _flat(results):
    """Learner results (MetricsLogger stats) as plain floats, like an iteration's result."""

    def value(v):
        return float(v.peek() if hasattr(v, "peek") else v)

    return {
        "learners": {
            mid: {k: value(v) for k, v in stats.items() if not isinstance(v, dict)}
            for mid, stats in results.items()
            if isinstance(stats, dict)
        }
    }


def test_the_proxy_is_trained_on_the_batch_and_the_policy_keeps_its_minibatches(monkeypatch):
    lrn = learner()
    proxy = trainer(lrn).proxy.rnd
    w = proxy.predictor[0].weight.clone()
    rows = rows_trained(monkeypatch)
    seen = policy_batches_seen(monkeypatch, lrn)
    update(lrn, episodes(0))
    assert not torch.equal(proxy.predictor[0].weight, w)
    assert not any(p.requires_grad for p in proxy.target.parameters())
    # the proxy trains once on the policy's 60 valid rows (aux_epochs unset), in minibatches
    # of the policy's 30; the discriminator once on the archive's states and the batch
    assert rows["proxy"] == 60 and rows["disc"] > 60
    # the policy: 2 epochs of its 66 rows (60 steps + 6 bootstrap rows) in minibatches of 30
    assert len(seen) == 5
    t = trainer(lrn)
    assert isinstance(t.disc_optimizer, torch.optim.Adam)
    assert t.disc_optimizer.param_groups[0]["weight_decay"] == 1e-4
    assert t.disc_optimizer.param_groups[0]["lr"] == pytest.approx(3e-4)
    assert t.proxy_optimizer.param_groups[0]["weight_decay"] == 0.0
    assert t.proxy_optimizer.param_groups[0]["lr"] == pytest.approx(1e-3)
    assert lrn.get_optimizers_for_module(DISC) == []  # RLlib steps nothing of ASOR's


@pytest.mark.parametrize(("epochs", "rows"), [(0.5, 30), (1, 60), (3, 180)])
def test_aux_epochs_sets_the_rows_the_aux_modules_train_on(monkeypatch, epochs, rows):
    lrn = learner(aux_epochs=epochs)
    trained = rows_trained(monkeypatch)
    update(lrn, episodes(0))
    # passes over the proxy's 60 rows in minibatches of 30, whatever the policy's epochs
    assert trained["proxy"] == rows


# ------------------------------------------------------------------ rewards
def test_rewards_before_gae_are_the_env_rewards_plus_lambda_times_log_omega():
    lrn = learner(preset="paper", mode="srpo", lambda_=0.1)
    eps = episodes(0)
    env_rewards = np.concatenate([np.append(e.get_rewards(), 0.0) for e in eps])
    disc_before = copy.deepcopy(trainer(lrn).state.disc)  # the piece trains it after the bonus
    batch = module_batch(lrn, episodes(0))
    pb = batch[DEFAULT_MODULE_ID]
    mask = pb[Columns.LOSS_MASK].bool()
    with torch.no_grad():
        logits = disc_before(pb[Columns.OBS][mask].float())
    expected = torch.as_tensor(env_rewards, dtype=torch.float32)[mask] + 0.1 * reward_bonus(
        logits, "log"
    )
    assert torch.allclose(pb[Columns.REWARDS][mask].float(), expected, atol=1e-5)
    # the advantages were computed from these rewards, with the values ASOR's pass shared
    assert Columns.ADVANTAGES in pb and Columns.VALUE_TARGETS in pb
    # nothing of ASOR's joins the train batch: its networks trained in the piece
    assert sorted(batch) == [DEFAULT_MODULE_ID]
    pieces_in_pipeline = [type(c) for c in lrn._learner_connector.connectors]
    assert pieces_in_pipeline.index(AsorRewardConnector) < pieces_in_pipeline.index(SharedValuesGAE)


def test_potential_shaping_on_ppo_takes_the_next_row_and_stops_at_termination():
    """r + λ(γ·b(s′) − b(s)), b = log ω before the step: in PPO's batch s′ of a valid row is the
    next row (a chunk's last s′ is its bootstrap row), and b(s′) = 0 where the episode ended."""
    lrn = learner(preset="paper", lambda_=0.5, shaping="potential")
    disc_before = copy.deepcopy(trainer(lrn).state.disc)
    eps = episodes(0)  # 6 terminated episodes of 10 steps: 11 rows each with the bootstrap row
    env = np.concatenate([np.append(e.get_rewards(), 0.0) for e in eps])
    pb = module_batch(lrn, eps)[DEFAULT_MODULE_ID]
    rows = pb[Columns.LOSS_MASK].bool().nonzero().squeeze(-1)
    with torch.no_grad():
        b = reward_bonus(disc_before(pb[Columns.OBS].float()), "log", -5.0)
    alive = torch.ones(60)
    alive[9::10] = 0.0  # the last step of each episode: terminated
    gamma = lrn.config.gamma
    expected = torch.as_tensor(env, dtype=torch.float32)[rows] + 0.5 * (
        gamma * b[rows + 1] * alive - b[rows]
    )
    torch.testing.assert_close(pb[Columns.REWARDS][rows].float(), expected)


def test_the_warm_up_waits_for_a_critic_that_explains_the_returns():
    """Robust default: no bonus while the critic's explained variance of the chunks' returns
    (bootstrapped with V at each truncated chunk's end) is ≤ 0; V ≡ 0 explains nothing."""
    lrn = learner(lambda_=0.3)
    for p in lrn.module[DEFAULT_MODULE_ID].unwrapped().vf.parameters():
        torch.nn.init.zeros_(p)
    eps = episodes(0, terminated=False)
    env = np.concatenate([np.append(e.get_rewards(), 0.0) for e in eps])
    rewards = module_batch(lrn, eps)[DEFAULT_MODULE_ID][Columns.REWARDS]
    torch.testing.assert_close(rewards, torch.as_tensor(env, dtype=rewards.dtype))
    assert trainer(lrn).state.critic_ready.item() == 0.0


def test_shared_values_are_the_critics_values():
    lrn = learner(preset="paper", mode="srpo", lambda_=0.0)
    batch = module_batch(lrn, episodes(0))
    pb = batch[DEFAULT_MODULE_ID]
    with torch.no_grad():
        vf = lrn.module[DEFAULT_MODULE_ID].compute_values({Columns.OBS: pb[Columns.OBS]})
    # λ = 0: rewards unchanged, so the value targets are GAE's with the critic's own values
    mask = pb[Columns.LOSS_MASK].bool()
    adv = pb[Columns.VALUE_TARGETS] - vf
    assert torch.allclose(adv[mask], pb[Columns.ADVANTAGES][mask] * 0 + adv[mask])
    # bootstrap rows hold V(s_T) of truncated chunks; terminated ones have target = reward
    last = torch.nonzero(mask).squeeze(-1)[9]  # the last valid row of the first episode
    assert pb[Columns.VALUE_TARGETS][last].item() == pytest.approx(
        pb[Columns.REWARDS][last].item(), abs=1e-5
    )


def test_rnd_per_dynamics_reads_the_dynamics_ids_of_the_episodes():
    lrn = learner(proxy="rnd_per_dynamics", dynamics_buckets=4)
    update(lrn, episodes(0))
    assert trainer(lrn).proxy.rnd.seen.tolist() == [1.0, 1.0, 1.0, 0.0]
    with pytest.raises(ValueError, match="dynamics_id"):
        update(lrn, episodes(1, ids=False))


@pytest.mark.parametrize("proxy", ["rnd", "ensemble"])
def test_proxies_other_than_per_dynamics_need_no_dynamics_ids(monkeypatch, proxy):
    lrn = learner(proxy=proxy)
    rows = rows_trained(monkeypatch)
    update(lrn, episodes(0, ids=False))
    assert rows["proxy"] == 60


def test_a_nan_observation_fails_with_a_clear_error():
    eps = episodes(0)
    eps[2].observations[3][1] = eps[4].observations[0][1] = np.nan
    with pytest.raises(ValueError, match=r"2 observation\(s\) of policy 'default_policy' .*NaN"):
        module_batch(learner(), eps)


def test_a_nan_reward_fails_naming_the_policy():
    eps = episodes(0)
    eps[1].rewards.data[4] = eps[3].rewards.data[0] = np.nan
    with pytest.raises(ValueError, match=r"2 reward\(s\) of policy 'default_policy' are NaN"):
        module_batch(learner(), eps)


def test_the_policys_minibatches_are_shuffled_when_asked(monkeypatch):
    seen = {}
    for shuffle in (False, True):
        lrn = learner()
        batches = policy_batches_seen(monkeypatch, lrn)
        lrn.update(
            episodes=episodes(0),
            timesteps={NUM_ENV_STEPS_SAMPLED_LIFETIME: 60},
            minibatch_size=30,
            num_epochs=2,
            shuffle_batch_per_epoch=shuffle,
        )
        monkeypatch.undo()
        seen[shuffle] = torch.cat([b[Columns.OBS] for b in batches])
    assert seen[False].shape == seen[True].shape == (150, 3)
    assert not torch.equal(seen[False], seen[True])


def test_the_connector_logs_the_last_updates_metrics_and_runs_without_a_logger(monkeypatch):
    seen, real = [], AsorTrainer.rank

    def spy(*args, **kwargs):
        seen.append(real(*args, **kwargs))
        return seen[-1]

    monkeypatch.setattr(AsorTrainer, "rank", spy)
    lrn, logger = learner(lambda_warmup=False), MetricsLogger()
    for seed in range(3):
        lrn._learner_connector(
            rl_module=lrn.module, batch={}, episodes=episodes(seed), metrics=logger
        )
    last = {k: float(v) for k, v in seen[-1].metrics.items()}
    assert len(last) > 3 and {k: logger.peek((DISC, k)) for k in last} == pytest.approx(last)
    batch = lrn._learner_connector(rl_module=lrn.module, batch={}, episodes=episodes(3))
    assert torch.isfinite(batch[DEFAULT_MODULE_ID][Columns.REWARDS]).all()


class DictObsPolicy(TorchRLModule, ValueFunctionAPI):
    """A linear policy and critic on every key of a Dict observation (PPO's default module
    takes Box observations only)."""

    def setup(self):
        width = sum(s.shape[0] for s in self.observation_space.spaces.values())
        self.pi = torch.nn.Linear(width, self.action_space.n)
        self.vf = torch.nn.Linear(width, 1)

    def _inputs(self, batch):
        return torch.cat([batch[Columns.OBS][k].float() for k in sorted(batch[Columns.OBS])], -1)

    def _forward(self, batch, **kwargs):
        return {Columns.ACTION_DIST_INPUTS: self.pi(self._inputs(batch))}

    def compute_values(self, batch, embeddings=None):
        return self.vf(self._inputs(batch)).squeeze(-1)


@pytest.mark.parametrize("proxy", ["rnd", "ensemble"])  # the ensemble also reads s′
def test_obs_keys_give_the_aux_modules_only_those_keys(monkeypatch, proxy):
    space = gym.spaces.Dict({"noise": gym.spaces.Box(-10, 10, (2,)), "pos": OBS})
    config = (
        PPOConfig()
        .environment(observation_space=space, action_space=ACT)
        .training(train_batch_size=60, minibatch_size=30, num_epochs=1)
        .rl_module(rl_module_spec=RLModuleSpec(module_class=DictObsPolicy))
    )
    config = rllib_asor.with_asor(config, **(SMALL | {"obs_keys": ["pos"], "proxy": proxy}))
    lrn = config.build_learner(
        env=None, spaces={"__env__": (space, ACT), DEFAULT_MODULE_ID: (space, ACT)}
    )
    eps = []
    for ep in episodes(0):  # the same states as "pos", a 100 times larger "noise" beside them
        obs = ep.get_observations()
        noisy = SingleAgentEpisode(observation_space=space, action_space=ACT)
        noisy.add_env_reset(observation={"noise": 100 + obs[0][:2], "pos": obs[0]}, infos={})
        for t in range(len(ep)):
            noisy.add_env_step(
                observation={"noise": 100 + obs[t + 1][:2], "pos": obs[t + 1]},
                action=ep.get_actions(t),
                reward=ep.get_rewards(t),
                terminated=ep.is_terminated and t == len(ep) - 1,
                extra_model_outputs={
                    k: ep.get_extra_model_outputs(k, t)
                    for k in (Columns.ACTION_LOGP, Columns.ACTION_DIST_INPUTS)
                },
            )
        eps.append(noisy.to_numpy())
    got = {}
    for method in ("train_discriminator", "train_proxy"):
        real = getattr(AsorTrainer, method)

        def spy(self, x, *args, _real=real, _name=method, **kwargs):
            got[_name] = x
            return _real(self, x, *args, **kwargs)

        monkeypatch.setattr(AsorTrainer, method, spy)
    module_batch(lrn, eps)
    states = torch.as_tensor(np.concatenate([e.get_observations()[:-1] for e in episodes(0)]))
    torch.testing.assert_close(got["train_proxy"].features, states)
    if proxy == "ensemble":
        after = torch.as_tensor(np.concatenate([e.get_observations()[1:] for e in episodes(0)]))
        torch.testing.assert_close(got["train_proxy"].next_features, after)
    disc = got["train_discriminator"]
    assert disc.shape[1] == 3 and disc.abs().max() < 10


def two_agent_episode() -> MultiAgentEpisode:
    """Agents "a" (3 steps, dynamics 1; its reset reports 4) and "b" (2 steps, then done,
    dynamics 2), each on its own module "pol_<agent>"; only "a" acts in the last step."""
    o = lambda: np.zeros(3, np.float32)  # noqa: E731
    ep = MultiAgentEpisode(agent_to_module_mapping_fn=lambda agent, episode: f"pol_{agent}")
    ep.add_env_reset(
        observations={"a": o(), "b": o()},
        infos={"a": {"dynamics_id": 4}, "b": {"dynamics_id": 2}},
    )
    for t in range(2):
        ep.add_env_step(
            observations={"a": o(), "b": o()},
            actions={"a": 0, "b": 0},
            rewards={"a": 0.0, "b": 0.0},
            infos={"a": {"dynamics_id": 1}, "b": {"dynamics_id": 2}},
            terminateds={"b": t == 1, "__all__": False},
            truncateds={"__all__": False},
        )
    ep.add_env_step(
        observations={"a": o()},
        actions={"a": 0},
        rewards={"a": 0.0},
        infos={"a": {"dynamics_id": 1}},
        terminateds={"__all__": False},
        truncateds={"__all__": False},
    )
    assert ep.get_agents_that_stepped() == {"a"}
    return ep


def test_dynamics_ids_cover_agents_that_did_not_step_last():
    """Multi-agent: every agent's rows get their ids, also an agent absent from the last step
    (RLlib's iterator would skip it by default, and its OBS rows would have no ids)."""
    ep = two_agent_episode()
    batch: dict = {}
    batch = AddObservationsFromEpisodesToBatch(as_learner_connector=True)(
        rl_module=None, batch=batch, episodes=[ep]
    )
    batch = AddDynamicsIdsToBatch()(rl_module=None, batch=batch, episodes=[ep])
    # columns map (episode id, agent id, module id) to that agent's rows
    ids = {key[1]: rows for key, rows in batch[DYNAMICS_ID].items()}
    obs = {key[1]: len(rows) for key, rows in batch[Columns.OBS].items()}
    assert ids == {"a": [4, 1, 1], "b": [2, 2]}
    assert {agent: len(rows) for agent, rows in ids.items()} == obs


# ------------------------------------------------------------------ checkpoints
@pytest.mark.parametrize(
    "settings",
    [
        {"lambda_": "auto", "lambda_init": 0.3, "lambda_lr": 0.5, "bonus_norm": "running"},
        {"preset": "paper", "proxy": "ensemble", "disc_input_norm": True},
    ],
    ids=["robust_auto_lambda", "paper_ensemble"],
)
def test_every_piece_of_state_survives_the_learners_checkpoint(settings, tmp_path):
    lrn = learner(**settings)
    for i in range(3):
        update(lrn, episodes(i), step=60 * (i + 1))
    saved = pieces(trainer(lrn).state, trainer(lrn).proxy)
    lrn.save_to_path(tmp_path / "learner")
    other = learner(**(settings | {"seed": 5}))
    fresh = pieces(trainer(other).state, trainer(other).proxy)
    assert fresh["auto_lambda"] != saved["auto_lambda"] or settings.get("lambda_") != "auto"
    assert not torch.equal(fresh["disc.0.weight"], saved["disc.0.weight"])
    other.restore_from_path(tmp_path / "learner")
    restored = pieces(trainer(other).state, trainer(other).proxy)
    assert restored.keys() == saved.keys()
    for name, value in saved.items():
        assert torch.allclose(restored[name], value, rtol=1e-6, atol=0), name
    assert all(is_aux_module(m) or m == DEFAULT_MODULE_ID for m in other.module.keys())
    # the optimisers' moments came back too: the next update is the same on both
    update(lrn, episodes(7), step=240)
    update(other, episodes(7), step=240)
    for a, b in zip(trainer(lrn).parameters(), trainer(other).parameters(), strict=True):
        torch.testing.assert_close(a, b)


def test_chunks_map_each_episode_to_its_valid_rows_key_and_dynamics():
    piece = learner()._asor_piece
    eps = episodes(0, n=3, length=4)
    eps[1].id_ = eps[1].id_ + "_7"  # RLlib's per-batch suffix on the learner's copy
    # PPO's rows: an episode as the Learner connector extended it by one step holds its real
    # steps (valid) and the bootstrap row (not valid): here 3 + 1 of each 4
    valid = torch.tensor(([True] * 3 + [False]) * 3)
    chunks = piece._chunks(eps, DEFAULT_MODULE_ID, valid)
    assert [(c.start, c.stop, c.dynamics_id) for c in chunks] == [(0, 3, 0), (3, 6, 1), (6, 9, 2)]
    assert [c.key for c in chunks] == [(e.id_.rsplit("_", 1)[0], e.agent_id) for e in eps]
    assert chunks[1].key[0] == eps[1].id_[: -len("_7")]
    # rows that do not match the episodes: no chunks (then no archive), never wrong ones
    assert piece._chunks(eps, DEFAULT_MODULE_ID, valid[:-1]) is None
    assert piece._chunks(eps, DEFAULT_MODULE_ID, torch.ones(12, dtype=torch.bool)) is None
    assert piece._chunks(None, DEFAULT_MODULE_ID, valid) is None
    assert piece._chunks(eps, "other_policy", valid) is None
    no_ids = piece._chunks(episodes(0, n=2, length=4, ids=False), DEFAULT_MODULE_ID, valid[:8])
    assert [c.dynamics_id for c in no_ids] == [0, 0]


def test_chunks_of_a_multi_agent_episode_per_module_with_the_first_states_dynamics():
    """Each module gets its agents' chunks, also those of an agent that did not act in the last
    step; a chunk's dynamics id is the one at its first state (the reset's)."""
    piece, ep = learner()._asor_piece, two_agent_episode()
    # as in PPO's batch, each episode's last row is its bootstrap row (not valid)
    a = piece._chunks([ep], "pol_a", torch.tensor([True, True, False]))
    b = piece._chunks([ep], "pol_b", torch.tensor([True, False]))
    assert [(c.key[1], c.start, c.stop, c.dynamics_id) for c in a] == [("a", 0, 2, 4)]
    assert [(c.key[1], c.start, c.stop, c.dynamics_id) for c in b] == [("b", 0, 1, 2)]


def test_a_policy_without_rows_in_the_batch_is_left_alone():
    lrn = ma_learner()
    batch = module_batch(lrn, ma_episodes(0, ("a0",)))  # "p1" did not act
    assert sorted(batch) == ["p0"]
    p1 = [p.detach().clone() for p in trainer(lrn, "p1").parameters()]
    assert all(torch.equal(a, b) for a, b in zip(p1, trainer(lrn, "p1").parameters(), strict=True))
    batch = module_batch(lrn, ma_episodes(1, ("a0", "a1")))
    assert batch["p1"][Columns.REWARDS].shape == (44,)
    assert any(
        not torch.equal(a, b) for a, b in zip(p1, trainer(lrn, "p1").parameters(), strict=True)
    )


def test_gae_on_shared_values_equals_gae_with_its_own_critic_pass(monkeypatch):
    """The critic runs once per batch (ASOR's pass); GAE's results are what a second pass
    gives. Without ASOR's values (the piece skipped), GAE runs the critic itself."""
    module_cls = type(learner().module[DEFAULT_MODULE_ID].unwrapped())
    calls = []
    real_values = module_cls.compute_values

    def counted(self, batch, *args, **kwargs):
        calls.append(len(batch[Columns.OBS]))
        return real_values(self, batch, *args, **kwargs)

    monkeypatch.setattr(module_cls, "compute_values", counted)
    shared = module_batch(learner(preset="paper", lambda_=0.0), episodes(0))[DEFAULT_MODULE_ID]
    assert calls == [66]  # one pass over the 60 steps + 6 bootstrap rows
    calls.clear()
    monkeypatch.setattr(
        AsorRewardConnector, "__call__", lambda self, *, batch, **kw: batch
    )  # no ASOR piece: no shared values
    own = module_batch(learner(preset="paper", lambda_=0.0), episodes(0))[DEFAULT_MODULE_ID]
    assert calls == [66]
    for key in (Columns.ADVANTAGES, Columns.VALUE_TARGETS):
        torch.testing.assert_close(shared[key], own[key])


def test_the_lambda_schedule_follows_the_env_steps_sampled():
    """λ = 0 at step 0 (and when the count is missing), 0.5 from step 1: the ASOR piece reads
    the timesteps the Learner gets."""
    lrn = learner(preset="paper", mode="srpo", lambda_=[[0, 0.0], [1, 0.5]])
    for step, expect in ((None, 0.0), (0, 0.0), (1, 0.5), (5, 0.5)):
        timesteps = {} if step is None else {NUM_ENV_STEPS_SAMPLED_LIFETIME: step}
        results = lrn.update(
            episodes=episodes(step or 0), timesteps=timesteps, minibatch_size=30, num_epochs=1
        )
        assert lift_asor_metrics(_flat(results))["lambda"] == pytest.approx(expect)


@pytest.mark.parametrize("aux_epochs", [None, 3])  # 3: more rows than the policy trains on
def test_the_policy_gets_its_minibatches_when_the_discriminator_batch_is_longer(
    monkeypatch, aux_epochs
):
    # robust: D_P from the archive, D_Q the whole batch
    lrn = learner(lambda_warmup=False, aux_epochs=aux_epochs)
    update(lrn, episodes(0))  # fills the archive
    rows = rows_trained(monkeypatch)
    seen = policy_batches_seen(monkeypatch, lrn)
    update(lrn, episodes(1), step=120, minibatch_size=10)
    assert rows["disc"] > 66 * (aux_epochs or 1)  # archive states + the whole batch
    # 2 epochs of 66 rows in minibatches of 10: 14, as without ASOR
    assert len(seen) == 14
