"""`MapleTorchRLModule`: MAPLE's networks, its dynamics ensemble and its data statistics.

One RLModule holds everything a checkpoint must bring back: the SAC networks
(`networks.MapleNetworks`: GRUs, actor, twin critics and their targets, log α), the trained
dynamics ensemble (`ensemble.GaussianEnsemble`, with its input normaliser and elite indices;
not trained by the Learner) and the data statistics the rollouts and targets use (state clip
range, Q-target range) as buffers.

Inference: the policy is recurrent (its context reads the history), so RLlib's stateless
`forward_inference` is only exact without a context (MOPO); MAPLE's own evaluation
(`evaluation.py`) steps the GRU. With a context, `forward_inference` raises.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.distribution.torch.torch_distribution import TorchSquashedGaussian
from ray.rllib.core.rl_module.torch import TorchRLModule

from rllib_asor.algorithms.maple.ensemble import GaussianEnsemble
from rllib_asor.algorithms.maple.networks import MapleNetworks
from rllib_asor.algorithms.maple.settings import MapleSettings


class MapleTorchRLModule(TorchRLModule):
    """See the module docstring; `model_config["maple"]` holds `MapleSettings` as a dict."""

    def setup(self) -> None:
        s = MapleSettings.from_dict(self.model_config.get("maple"))
        obs_dim = int(self.observation_space.shape[0])
        act_dim = int(self.action_space.shape[0])
        self.settings = s
        self.nets = MapleNetworks(
            obs_dim, act_dim, s.context, s.gru_hidden, s.context_dim, tuple(s.hiddens)
        )
        self.ensemble = GaussianEnsemble(
            obs_dim,
            act_dim,
            s.ensemble_members,
            s.ensemble_elites,
            s.ensemble_hidden,
            s.ensemble_layers,
        )
        self.ensemble.requires_grad_(False)
        self.register_buffer("obs_lo", torch.full((obs_dim,), -1e6))
        self.register_buffer("obs_hi", torch.full((obs_dim,), 1e6))
        self.register_buffer("reward_range", torch.tensor([-1e6, 1e6]))
        """[r_lo, r_hi]: model rewards are clipped to it; Q targets to it / (1 − γ)."""
        self.register_buffer("ensemble_ready", torch.tensor(0.0))

    def _forward_inference(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        if self.nets.use_context:
            raise ValueError(
                "MAPLE's policy is recurrent: RLlib's stateless forward_inference cannot run it; "
                "use rllib_asor.algorithms.maple.evaluation.evaluate (or MOPO, context off)"
            )
        mu, log_std = self.nets.actor.dist_inputs(None, batch[Columns.OBS].float())
        return {Columns.ACTION_DIST_INPUTS: torch.cat([mu, log_std], dim=-1)}

    def _forward_exploration(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        return self._forward_inference(batch, **kwargs)

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        return {}  # the Learner runs the segment losses itself (losses.maple_losses)

    def get_inference_action_dist_cls(self) -> type:
        return TorchSquashedGaussian

    def get_exploration_action_dist_cls(self) -> type:
        return TorchSquashedGaussian

    def get_train_action_dist_cls(self) -> type:
        return TorchSquashedGaussian
