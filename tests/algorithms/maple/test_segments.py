"""Segments, hidden states, GRU contexts, the 5 %/95 % mix, the masked losses, ASOR rows."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from rllib_asor.algorithms.maple.losses import maple_losses, state_values
from rllib_asor.algorithms.maple.networks import MapleNetworks, segment_contexts
from rllib_asor.algorithms.maple.segments import (
    RealSegments,
    SegmentPool,
    Trajectories,
    episode_hiddens,
    mix_sizes,
    mixed_batch,
    segment_starts,
)
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.update import AsorState
from tests.rllib.test_soft_q_glue import maple_asor_bonus, real_batch


def _episode(t: int, start: float, done: bool, obs_dim: int = 2) -> tuple:
    obs = start + np.arange(t + 1, dtype=np.float32)[:, None] * np.ones((1, obs_dim), np.float32)
    act = np.arange(t, dtype=np.float32)[:, None] + 100 * start
    return obs, act, np.full(t, start, np.float32), done


def _traj() -> Trajectories:
    return Trajectories.from_episodes([_episode(5, 0.0, True), _episode(3, 1.0, False)], [0, 2])


def test_episodes_become_h_step_segments_from_each_episode_start() -> None:
    traj = _traj()
    first, size = segment_starts(traj.starts, traj.lengths, 2)
    assert first.tolist() == [0, 2, 4, 5, 7] and size.tolist() == [2, 2, 1, 2, 1]
    assert traj.last_actions[:, 0].tolist() == [0, 0, 1, 2, 3, 0, 100, 101]
    assert traj.terminateds.tolist() == [False] * 4 + [True] + [False] * 3
    assert traj.dynamics_ids.tolist() == [0] * 5 + [2] * 3
    seg = RealSegments(traj, 2).gather(np.array([2, 4]))
    assert seg["valid"].tolist() == [[True, False], [True, False]]
    assert seg["terminateds"].tolist() == [[True, False], [False, False]]  # only the real end
    assert seg["obs"][:, 1].tolist() == [[0, 0], [0, 0]]  # padding is zero
    np.testing.assert_allclose(seg["next_obs"][0, 0], [5, 5])


def test_hidden_states_are_the_gru_state_before_each_step_zero_at_episode_starts() -> None:
    traj = _traj()

    def cumulative(obs: np.ndarray, last: np.ndarray) -> np.ndarray:
        return np.cumsum(obs[..., :1], axis=1)  # "GRU state" = running sum of obs[0]

    h = episode_hiddens(traj, cumulative, per_call=1)
    assert h[:, 0].tolist() == [0, 0, 1, 3, 6, 0, 1, 3]


def test_segment_contexts_continue_the_trajectory_from_the_refreshed_hidden_state() -> None:
    torch.manual_seed(0)
    nets = MapleNetworks(2, 1, gru_hidden=8, context_dim=4, hiddens=(16,))
    traj = Trajectories.from_episodes(
        [
            (
                np.random.randn(7, 2).astype(np.float32),
                np.random.randn(6, 1).astype(np.float32),
                np.zeros(6, np.float32),
                False,
            )
        ]
    )
    full = nets.hidden_sequences("value", traj.obs[None], traj.last_actions[None])[0]  # [6, H]
    hid = episode_hiddens(traj, lambda o, a: nets.hidden_sequences("value", o, a))
    segs = RealSegments(traj, 4, (8, 8))
    segs.set_hiddens(hid, hid)
    b = {k: torch.as_tensor(v) for k, v in segs.gather(np.array([1])).items()}  # rows 4, 5
    ctx, nxt = segment_contexts(
        nets.value_gru,
        b["obs"],
        b["last_actions"],
        b["actions"],
        b["next_obs"],
        b["valid"],
        b["value_hidden"],
    )
    torch.testing.assert_close(ctx[0, :2], torch.as_tensor(full[4:6]), rtol=1e-5, atol=1e-5)
    # the next state's context of step 4 is step 5's; of the last valid step one GRU step more
    torch.testing.assert_close(nxt[0, 0], ctx[0, 1])
    extra = nets.value_gru.step(b["next_obs"][:, 1], b["actions"][:, 1], ctx[:, 1])
    torch.testing.assert_close(nxt[0, 1], extra[0])


def test_mix_is_5_percent_real_and_95_percent_model_segments() -> None:
    assert mix_sizes(256, 0.05) == (12, 244)
    traj = _traj()
    real = RealSegments(traj, 3)
    pool = SegmentPool(4)
    model = {k: v for k, v in real.gather(np.array([0, 1, 2])).items()}
    model["obs"] = model["obs"] + 1000.0  # tell them apart
    pool.add(model)
    pool.add(model)  # ring buffer: wraps at capacity 4
    assert len(pool) == 4 and pool.pointer == 2
    batch = mixed_batch(real, pool, 40, 0.05, np.random.default_rng(0))
    assert batch["is_real"].sum() == 2 and len(batch["is_real"]) == 40
    assert (batch["obs"][:2] < 1000).all() and (batch["obs"][2:][batch["valid"][2:]] >= 1000).all()
    assert batch["obs"].shape[1] == batch["valid"].sum(1).max()


def test_pool_state_round_trip_keeps_the_ring_order_and_the_newest_segments() -> None:
    pool = SegmentPool(4)
    for i in range(6):  # wraps: holds 2, 3, 4, 5 with the oldest (2) at the pointer
        pool.add({"obs": np.full((1, 3, 2), i, np.float32)})
    same = SegmentPool(4)
    same.set_state(pool.get_state())
    assert len(same) == 4
    same.add({"obs": np.full((1, 3, 2), 6, np.float32)})  # overwrites the oldest: 2
    assert sorted(same.data["obs"][:, 0, 0].tolist()) == [3, 4, 5, 6]
    smaller = SegmentPool(2)
    smaller.set_state(pool.get_state())
    assert sorted(smaller.data["obs"][:, 0, 0].tolist()) == [4, 5]
    empty = SegmentPool(4)
    empty.set_state(SegmentPool(4).get_state())
    assert len(empty) == 0


def _segment_batch(nets: MapleNetworks, b: int = 6, t: int = 4) -> dict[str, torch.Tensor]:
    g = torch.Generator().manual_seed(0)
    valid = torch.ones(b, t, dtype=torch.bool)
    valid[0, 2:] = False
    return {
        "obs": torch.randn(b, t, 2, generator=g),
        "actions": torch.rand(b, t, 1, generator=g) * 2 - 1,
        "next_obs": torch.randn(b, t, 2, generator=g),
        "last_actions": torch.rand(b, t, 1, generator=g),
        "rewards": torch.randn(b, t, generator=g),
        "terminateds": torch.zeros(b, t, dtype=torch.bool),
        "valid": valid,
        "policy_hidden": torch.zeros(b, nets.gru_hidden),
        "value_hidden": torch.zeros(b, nets.gru_hidden),
    }


@pytest.mark.parametrize("context", [True, False])
def test_losses_ignore_padding_and_clip_the_targets(context: bool) -> None:
    torch.manual_seed(0)
    nets = MapleNetworks(2, 1, context=context, gru_hidden=8, context_dim=4, hiddens=(16,))
    b = _segment_batch(nets)
    kw = dict(gamma=0.99, target_entropy=-1.0, q_lo=-0.5, q_hi=0.5)
    torch.manual_seed(1)
    losses, stats = maple_losses(nets, b, **kw)
    b2 = dict(b)
    b2["rewards"] = b["rewards"].clone()
    b2["rewards"][0, 2:] = 1e6  # padding: must not matter
    torch.manual_seed(1)
    losses2, _ = maple_losses(nets, b2, **kw)
    for k in losses:
        torch.testing.assert_close(losses[k], losses2[k])
    assert -0.5 <= stats["target_mean"] <= 0.5
    assert stats["valid_fraction"] == pytest.approx(22 / 24)
    # the critic loss reaches the value GRU, the actor loss the policy GRU
    losses["critic"].backward(retain_graph=True)
    if context:
        assert nets.value_gru.gru.weight_ih_l0.grad is not None
        assert nets.policy_gru.gru.weight_ih_l0.grad is None
    v = state_values(
        nets, b["obs"][:, 0], b["last_actions"][:, 0], b["policy_hidden"], b["value_hidden"]
    )
    assert v.shape == (6,)


def test_asor_bonus_reaches_every_valid_row_real_and_model() -> None:
    cfg = AsorConfig.from_dict({"preset": "paper", "lambda_": 0.1, "mode": "srpo", "seed": 0})
    state = AsorState(cfg, 2)
    g = torch.Generator().manual_seed(0)
    real_obs = torch.randn(32, 2, generator=g)
    values = real_obs[:, 0]  # the upper half by value is "real"
    rb = real_batch(
        real_obs,
        real_obs + 0.1,
        torch.ones(32),
        torch.zeros(32, dtype=torch.bool),
        values,
        gamma=0.99,
        timestep=0.0,
    )
    obs = torch.randn(5, 3, 2, generator=g)  # 5 segments (say 1 real, 4 model), 3 steps
    valid = torch.ones(5, 3, dtype=torch.bool)
    valid[4, 1:] = False
    delta, result = maple_asor_bonus(
        cfg,
        state,
        None,
        rb,
        obs,
        obs,
        torch.zeros(5, 3, dtype=torch.bool),
        valid,
        np.random.default_rng(0),
    )
    logits = state.disc(obs.reshape(-1, 2)).reshape(5, 3)
    expected = 0.1 * torch.nn.functional.logsigmoid(logits).clamp(min=cfg.log_omega_min)
    torch.testing.assert_close(delta[valid], expected[valid])
    assert (delta[~valid] == 0).all() and (delta[valid] < 0).all()
    # the discriminator's batch is the real states, the upper half by value labelled 1
    assert result.disc_features.shape == (32, 2)
    assert result.disc_labels.sum().item() == 16
    assert set(values[result.disc_labels > 0.5].tolist()) == set(values.topk(16).values.tolist())


def test_robust_asor_bonus_on_valid_rows_ignores_padding() -> None:
    # the robust default (batch norm, potential form); value-only partition: no proxy needed
    cfg = AsorConfig.from_dict({"seed": 0, "mode": "srpo"})
    g = torch.Generator().manual_seed(0)
    real_obs = torch.randn(32, 2, generator=g)
    rb = real_batch(
        real_obs,
        real_obs + 0.1,
        torch.ones(32),
        torch.zeros(32, dtype=torch.bool),
        real_obs[:, 0],
        gamma=0.99,
        timestep=0.0,
    )
    obs = torch.randn(4, 3, 2, generator=g)
    valid = torch.ones(4, 3, dtype=torch.bool)
    valid[0, 1:] = False
    term = torch.zeros(4, 3, dtype=torch.bool)
    out = []
    for pad in (0.0, 1e3):  # what padding holds must not matter
        o = obs.clone()
        o[~valid] = pad
        torch.manual_seed(0)
        state = AsorState(cfg, 2)
        delta, result = maple_asor_bonus(
            cfg, state, None, rb, o, o + 0.05, term, valid, np.random.default_rng(0)
        )
        out.append(delta)
    torch.testing.assert_close(out[0], out[1])
    assert (out[0][~valid] == 0).all() and (out[0][valid] != 0).any()
    assert result.metrics["potential"] == 1.0
