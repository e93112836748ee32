"""Overlapped PPO's lag correction (`rllib_asor.algorithms.ppo.lag`): truncated importance
weights on hand-made numbers, the piece on a real PPO module, and in an overlapped run."""

from __future__ import annotations

import math

import gymnasium as gym
import pytest
import torch
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.evaluation.postprocessing import Postprocessing
from ray.rllib.utils.metrics.metrics_logger import MetricsLogger

from rllib_asor.algorithms.ppo.lag import ProximalCorrection, lag_weights
from rllib_asor.algorithms.ppo.overlap import overlap_sampling


def test_weights_are_the_truncated_ratio_of_proximal_to_behaviour() -> None:
    prox = torch.log(torch.tensor([0.5, 0.2, 0.3]))
    behaviour = torch.log(torch.tensor([0.25, 0.4, 0.3]))
    assert lag_weights(prox, behaviour, clip=1.0).tolist() == pytest.approx([1.0, 0.5, 1.0])
    assert lag_weights(prox, behaviour, clip=3.0).tolist() == pytest.approx([2.0, 0.5, 1.0])
    with pytest.raises(ValueError, match="lag_weight_clip"):
        ProximalCorrection(weight_clip=0.0)


def test_piece_takes_the_current_policy_and_weights_the_advantages() -> None:
    from ray.rllib.algorithms.ppo.torch.default_ppo_torch_rl_module import (
        DefaultPPOTorchRLModule,
    )

    env = gym.make("CartPole-v1")
    torch.manual_seed(0)
    module = RLModuleSpec(
        module_class=DefaultPPOTorchRLModule,
        observation_space=env.observation_space,
        action_space=env.action_space,
        model_config={"fcnet_hiddens": [8]},
    ).build()
    obs = torch.randn(4, 4)
    actions = torch.tensor([0, 1, 0, 1])
    with torch.no_grad():
        logits = module.forward_train({Columns.OBS: obs})[Columns.ACTION_DIST_INPUTS]
    current = torch.distributions.Categorical(logits=logits).log_prob(actions)
    # behaviour: twice as likely (w = 0.5), half as likely (w = 2 -> 1), equal (w = 1), 4x (0.25)
    behaviour = current + torch.log(torch.tensor([2.0, 0.5, 1.0, 4.0]))
    rows = {
        Columns.OBS: obs,
        Columns.ACTIONS: actions,
        Columns.ACTION_LOGP: behaviour,
        Columns.ACTION_DIST_INPUTS: torch.zeros(4, 2),
        Postprocessing.ADVANTAGES: torch.tensor([1.0, -2.0, 3.0, 4.0]),
    }
    metrics = MetricsLogger()

    class One(dict):  # a MultiRLModule's item access
        pass

    out = ProximalCorrection()(rl_module=One(p=module), batch={"p": rows}, metrics=metrics)["p"]
    assert out[Postprocessing.ADVANTAGES].tolist() == pytest.approx([0.5, -2.0, 3.0, 1.0])
    assert out[Columns.ACTION_LOGP].tolist() == pytest.approx(current.tolist(), abs=1e-6)
    assert torch.allclose(out[Columns.ACTION_DIST_INPUTS], logits)
    logged = metrics.reduce()["p"]
    assert float(logged["lag/logp_gap"]) == pytest.approx(
        (2 * math.log(2) + 0 + math.log(4)) / 4, abs=1e-5
    )
    assert float(logged["lag/truncated_fraction"]) == pytest.approx(0.25)


def _overlapped(**lcd) -> PPOConfig:
    config = (
        PPOConfig()
        .environment("CartPole-v1")
        .env_runners(num_env_runners=1, num_envs_per_env_runner=2)
        .training(train_batch_size=400, minibatch_size=100, num_epochs=2)
        .debugging(seed=0)
    )
    config = overlap_sampling(config)
    return config.learners(learner_config_dict={**config.learner_config_dict, **lcd})


def test_switched_off_an_overlapped_run_reports_no_lag(ray_session) -> None:
    """Switched on (the default), an overlapped run reports the lag it corrects:
    tests/algorithms/test_overlap.py checks it in its learning run."""
    off = _overlapped(lag_correction=False).build_algo()
    try:
        assert "lag/logp_gap" not in off.train()["learners"]["default_policy"]
    finally:
        off.stop()
