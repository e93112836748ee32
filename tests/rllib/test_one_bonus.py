"""The bonus is normalised and shaped in one place (`asor.update`): the piece's bonus on
rows other than the ranked ones (MAPLE's SAC rows, `connector.bonus_on_rows`) is
`asor_update`'s own reward delta when those rows are the ranked ones, for every normalisation
and shaping."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.reward import potential_shaping, reward_bonus, standardize
from rllib_asor.asor.update import AsorState, asor_update
from tests.rllib.test_soft_q_glue import maple_asor_bonus, real_batch


def _real(n: int = 48, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    obs = torch.randn(n, 3, generator=g)
    nxt = obs + 0.1 * torch.randn(n, 3, generator=g)
    term = torch.rand(n, generator=g) < 0.2
    rewards = torch.randn(n, generator=g)
    return real_batch(obs, nxt, rewards, term, obs[:, 0], gamma=0.9, timestep=0.0)


@pytest.mark.parametrize("bonus_norm", ["running", "batch", "off"])
@pytest.mark.parametrize("shaping", ["potential", "direct"])
def test_maple_bonus_on_the_ranked_rows_is_asor_updates_reward_delta(bonus_norm, shaping):
    cfg = AsorConfig.from_dict(
        {
            "seed": 0,
            "mode": "srpo",
            "lambda_": 0.5,
            "bonus_norm": bonus_norm,
            "shaping": shaping,
            "lambda_relative": False,
            "bonus_share_max": 0.0,
        }
    )
    torch.manual_seed(0)
    state = AsorState(cfg, 3)
    twin = copy.deepcopy(state)
    real = _real()
    reference = asor_update(cfg, twin, None, real, np.random.default_rng(0))
    valid = torch.ones(real.features.shape[0], dtype=torch.bool)
    delta, result = maple_asor_bonus(
        cfg,
        state,
        None,
        real,
        real.features,
        real.next_features,
        real.terminateds,
        valid,
        np.random.default_rng(0),
    )
    assert result.lam == pytest.approx(0.5) and reference.lam == pytest.approx(0.5)
    assert delta.abs().sum() > 0
    torch.testing.assert_close(delta, reference.reward_delta)
    torch.testing.assert_close(state.bonus_rms.mean, twin.bonus_rms.mean)  # updated once


def test_model_rows_take_their_own_batch_statistics_and_the_running_ones_unchanged():
    real = _real()
    g = torch.Generator().manual_seed(1)
    obs, nxt = torch.randn(6, 4, 3, generator=g), torch.randn(6, 4, 3, generator=g)
    term = torch.zeros(6, 4, dtype=torch.bool)
    term[:, -1] = True
    valid = torch.ones(6, 4, dtype=torch.bool)
    valid[5, 2:] = False
    for bonus_norm in ("batch", "running"):
        cfg = AsorConfig.from_dict({"seed": 0, "mode": "srpo", "bonus_norm": bonus_norm})
        torch.manual_seed(0)
        state = AsorState(cfg, 3)
        delta, result = maple_asor_bonus(
            cfg, state, None, real, obs, nxt, term, valid, np.random.default_rng(0)
        )
        rms = (state.bonus_rms.mean.clone(), state.bonus_rms.var.clone())
        with torch.no_grad():
            raw = reward_bonus(
                state.disc(obs[valid]), cfg.reward_form, cfg.log_omega_min, cfg.logit_clip
            )
            raw_next = reward_bonus(
                state.disc(nxt[valid]), cfg.reward_form, cfg.log_omega_min, cfg.logit_clip
            )
        mean, var = (
            (raw.mean(), raw.var(unbiased=False))
            if bonus_norm == "batch"
            else (rms[0].reshape(()), rms[1].reshape(()))
        )
        b = standardize(raw, mean, var, cfg.bonus_clip)
        nb = standardize(raw_next, mean, var, cfg.bonus_clip)
        expected = result.lam * potential_shaping(b, nb, term[valid], real.gamma)
        assert result.lam > 0
        torch.testing.assert_close(delta[valid], expected)
        assert (delta[~valid] == 0).all()
        torch.testing.assert_close(state.bonus_rms.mean, rms[0])  # the SAC rows left it alone
