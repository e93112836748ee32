"""UP-OSI's RLModule: the universal policy π(a | s, μ), twin Q(s, a, μ) and OSI μ̂ = OSI(window).

ESCP's module (`rllib_asor.algorithms.escp.module`) with its context encoder replaced by the
OSI network and its context by the dynamics parameters: in training π and the critics read the
true μ of each replayed step (the batch's `osi_params` column; the authors train the universal
policy on the true parameters), OSI's estimate is the `escp_context` output that OSI's loss
regresses; when acting (exploration and inference) π reads μ̂ from the window the env runner
hands it, as the authors' `OSIEnvWrapper` feeds OSI's estimate to the policy.
"""

from __future__ import annotations

from typing import Any

import torch
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.escp.module import EscpTorchRLModule
from rllib_asor.algorithms.escp.replay import WINDOW
from rllib_asor.algorithms.osi.network import OsiNetwork
from rllib_asor.algorithms.osi.replay import PARAMS
from rllib_asor.algorithms.osi.settings import OsiSettings

OSI_KEY = "osi"
"""`model_config` key of the validated `OsiSettings` dict (set by OsiConfig)."""


class OsiTorchRLModule(EscpTorchRLModule):
    """π(a | s, μ), Q(s, a, μ) ×2 (+ targets), OSI(window) → μ̂ (module docstring)."""

    def setup(self) -> None:
        super().setup()  # ESCP's π, critics and encoder, with context_dim = param_dim
        self.osi = OsiSettings.from_dict((self.model_config or {}).get(OSI_KEY))
        step_dim = int(self.observation_space.shape[0]) + int(self.action_space.shape[0])
        self.encoder = OsiNetwork(
            self.escp.history_len, step_dim, self.escp.context_dim, self.osi.osi_hidden
        )

    def critic_context(self, dynamics_id: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        raise NotImplementedError("OSI's critics read the true parameters (batch[osi_params])")

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        """SAC's quantities with the true μ for π and the critics; OSI's μ̂ (with gradient)."""
        mu = batch[PARAMS].float()
        return self.sac_outputs(batch, self.context(batch[WINDOW]), mu, mu, mu)

    def forward_target(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        mu = batch[PARAMS].float()
        return {"q_target": self._q(batch[Columns.OBS], batch[Columns.ACTIONS], mu, target=True)}

    def compute_q_values(self, batch: dict[str, Any], squeeze: bool = True) -> torch.Tensor:
        return self._q(batch[Columns.OBS], batch[Columns.ACTIONS], batch[PARAMS].float())

    def state_values(self, batch: dict[str, Any], context: str | None = None) -> torch.Tensor:
        """V(s) = min Q(s, π's deterministic action, μ), μ the true parameters (ASOR's
        ranking)."""
        obs, mu = batch[Columns.OBS], batch[PARAMS].float()
        action = torch.tanh(self.policy_inputs(obs, mu).chunk(2, dim=-1)[0])
        return self._q(obs, action, mu)
