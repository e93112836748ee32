"""CaDM's RLModule (model-free variant): π(a | s, c) and twin Q(s, a, c), c = CaDM's context of
the last H steps.

ESCP's module (`rllib_asor.algorithms.escp.module`) with its encoder replaced by `CadmModel`
(the context network, plus the forward and backward models that train it) and the critics fed
the context itself (ESCP feeds them a per-task moving average): π and the critics read c
without gradient, as the authors' PPO reads the dynamics model's context
(`cadm/model_free/ppo_cadm.py extract_context`); only CaDM's prediction loss trains it.
"""

from __future__ import annotations

import torch

from rllib_asor.algorithms.cadm.model import CadmModel
from rllib_asor.algorithms.cadm.settings import CadmSettings
from rllib_asor.algorithms.escp.module import EscpTorchRLModule

CADM_KEY = "cadm"
"""`model_config` key of the validated `CadmSettings` dict (set by CadmConfig)."""


class CadmTorchRLModule(EscpTorchRLModule):
    """π(a | s, c), Q(s, a, c) ×2 (+ targets), c = CaDM's context (module docstring)."""

    def setup(self) -> None:
        super().setup()  # ESCP's π, critics (context_dim = CaDM's) and encoder, replaced here
        self.cadm = CadmSettings.from_dict((self.model_config or {}).get(CADM_KEY))
        self.encoder = CadmModel(
            int(self.observation_space.shape[0]),
            int(self.action_space.shape[0]),
            self.cadm.history_len,
            self.cadm.context_dim,
            self.cadm.context_hidden,
            self.cadm.model_hidden,
        )

    def critic_context(self, dynamics_id: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """The critics read the context itself, without gradient (no task ids needed)."""
        return z.detach()

    def task_mean_context(self, dynamics_id: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
        return self.context(window).detach()
