"""The one episode loop (`rllib_asor.evaluation.rollout`) and the per-algorithm actors it runs:
batched and one-at-a-time episodes agree, each episode gets a fresh actor, ESCP's inference
window holds the last H (s, a_prev) rows zero-padded, MAPLE's GRU state starts at zero in every
episode, and `summarize` gives `rllib evaluate`'s numbers per dynamics id."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from ray.rllib.env.single_agent_episode import SingleAgentEpisode

import rllib_asor  # noqa: F401  (registers our env ids)
from rllib_asor.evaluation.rollout import play, rollout, unsquash
from rllib_asor.evaluation.summary import summarize


def _lean(obs, info):  # a deterministic CartPole policy: push towards the pole's lean
    return int(obs[2] > 0)


def test_envs_stepped_together_give_the_episodes_of_one_env_at_a_time() -> None:
    seeds = [0, 1, 2, 3]
    envs = [gym.make("CartPole-v1") for _ in seeds]
    batch_sizes: list[int] = []

    def policy(obs, infos):
        batch_sizes.append(len(obs))
        return [_lean(o, i) for o, i in zip(obs, infos, strict=True)]

    together = play(envs, seeds, policy)
    alone = rollout(lambda: _lean, "CartPole-v1", len(seeds), seed=0)
    assert [ep.total_reward for ep in together] == alone.returns
    assert [ep.length for ep in together] == alone.lengths
    assert len(set(alone.lengths)) > 1  # the episodes end at different steps ...
    assert batch_sizes[0] == 4 and batch_sizes[-1] == 1  # ... and finished envs drop out
    assert sorted(batch_sizes, reverse=True) == batch_sizes
    assert all(ep.terminated for ep in together)  # the pole fell (no 500-step truncation)


def test_every_episode_gets_a_fresh_actor_and_its_reset_seed() -> None:
    made: list[int] = []

    def actor():
        made.append(len(made))
        return _lean

    first = rollout(actor, "CartPole-v1", 3, seed=10)
    assert made == [0, 1, 2]
    assert rollout(actor, "CartPole-v1", 1, seed=11).returns == first.returns[1:2]


def _escp_module():
    from rllib_asor.algorithms.escp.config import EscpConfig

    env = gym.make("Pendulum-v1")
    try:
        spec = (
            EscpConfig().environment("Pendulum-v1").escp(history_len=4).get_rl_module_spec(env=env)
        )
        return spec.build()
    finally:
        env.close()


def test_escp_sees_the_last_h_observations_and_actions_zero_padded() -> None:
    from rllib_asor.algorithms.escp import evaluate as escp
    from rllib_asor.algorithms.escp.replay import WINDOW

    torch.manual_seed(0)
    module = _escp_module()
    windows: list[np.ndarray] = []
    forward = module.forward_inference

    def spy(batch, **kw):
        windows.append(batch[WINDOW][0].cpu().numpy().copy())
        return forward(batch, **kw)

    module.forward_inference = spy
    actions: list[np.ndarray] = []
    observations: list[np.ndarray] = []
    actor = escp.EscpActor(module, record_context=True)

    def watched():
        step = actor()

        def inner(obs, info):
            observations.append(np.asarray(obs, np.float32))
            actions.append(step(obs, info))
            return actions[-1]

        return inner

    rollout(watched, "Pendulum-v1", 2, env_kwargs={"max_episode_steps": 6}, action_fn=unsquash)
    assert len(windows) == 12 and len(actor.contexts) == 2
    assert all(len(z) == 6 for z in actor.contexts)
    for t in range(6):
        for e in (0, 1):  # the second episode starts from zeros again
            w, k = windows[6 * e + t], 6 * e + t
            prev = actions[k - 1] if t > 0 else np.zeros(1, np.float32)
            np.testing.assert_allclose(w[-1], np.concatenate([observations[k], prev]), rtol=1e-6)
            assert np.all(w[: max(0, 4 - t - 1)] == 0)
    assert all(np.all(np.abs(a) <= 1) for a in actions)  # tanh(μ), before the unsquash


def test_maple_starts_every_episode_from_a_zero_hidden_state() -> None:
    from rllib_asor.algorithms.maple.evaluation import maple_actor
    from rllib_asor.algorithms.maple.networks import MapleNetworks

    torch.manual_seed(0)
    nets = MapleNetworks(3, 1, gru_hidden=8, context_dim=4, hiddens=(16,))
    kw = {"env_kwargs": {"max_episode_steps": 20}, "action_fn": unsquash}
    both = rollout(maple_actor(nets), "Pendulum-v1", 2, seed=5, **kw)
    second = rollout(maple_actor(nets), "Pendulum-v1", 1, seed=6, **kw)
    assert both.returns[1] == second.returns[0]
    assert both.returns[0] != both.returns[1]


def _episode(seed: int, dynamics: int) -> SingleAgentEpisode:
    env = gym.make("CartPole-v1")
    obs, _ = env.reset(seed=seed)
    ep = SingleAgentEpisode(observations=[obs], infos=[{"dynamics_id": dynamics}])
    done = False
    while not done:
        action = _lean(obs, {})
        obs, r, term, trunc, _ = env.step(action)
        info = {"dynamics_id": dynamics}
        ep.add_env_step(obs, action, r, infos=info, terminated=term, truncated=trunc)
        done = term or trunc
    env.close()
    return ep


def test_summary_gives_returns_per_dynamics_id() -> None:
    eps = [_episode(0, 1), _episode(1, 1), _episode(2, np.int64(2))]
    stats = summarize(eps)
    returns = [float(ep.get_return()) for ep in eps]
    assert stats["returns"] == returns and stats["dynamics_ids"] == [1, 1, 2]
    assert stats["return_mean"] == pytest.approx(np.mean(returns))
    assert stats["return_std"] == pytest.approx(np.std(returns))
    assert stats["per_dynamics"] == {
        "1": {"episodes": 2, "return_mean": pytest.approx(np.mean(returns[:2]))},
        "2": {"episodes": 1, "return_mean": returns[2]},
    }
