"""ESCP's RLModule: π(a | s, z) and twin Q(s, a, z) with a context encoder z = φ(window).

ESCP `models/policy.py` (`Policy`: the "universe policy" `up` on s ⊕ z, with z from the
environment probe `ep`) and `models/value.py` (`Value`: `up` on s ⊕ z ⊕ a), with the run
settings `--stop_pg_for_ep --bottle_neck` (`parameter/Parameter.py`):

- π and Q are MLPs of `fcnet_hiddens` (ESCP: 128, 64) with LeakyReLU (`up_activations`);
  the policy head is a tanh-squashed Gaussian with log σ clipped to [−7, 2] (`Policy.forward`);
- z enters π detached (`stop_pg_for_ep`: no RL gradient into the encoder), with N(0, 0.01²)
  noise when sampling for training (`bottle_neck`), without at inference;
- the critics are fed a per-task moving average of z (`SAC.sac_update`: `ep_current =
  rmdm_loss.history_env_mean[task − 1]`), kept here as buffers (`task_means`, `task_seen`,
  `task_ids`), so they are checkpointed with the module.

On the env runner the module reads `batch["escp_window"]` (connector.py); in the Learner the
batch also holds the target's window and the task ids (replay.py).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.distribution.torch.torch_distribution import (
    TorchDeterministic,
    TorchSquashedGaussian,
)
from ray.rllib.core.learner.utils import make_target_network
from ray.rllib.core.rl_module.apis import InferenceOnlyAPI, QNetAPI, TargetNetworkAPI
from ray.rllib.core.rl_module.torch.torch_rl_module import TorchRLModule
from torch import nn

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.escp.encoder import ContextEncoder, add_context_noise
from rllib_asor.algorithms.escp.replay import DYNAMICS_ID, NEXT_WINDOW, WINDOW
from rllib_asor.algorithms.escp.rmdm import TaskSlots
from rllib_asor.algorithms.escp.settings import EscpSettings
from rllib_asor.algorithms.sac.fast import TrainModeOnceMixin

ESCP_KEY = "escp"
"""`model_config` key of the validated `EscpSettings` dict (set by EscpConfig)."""
CONTEXT = "escp_context"
"""Forward output: the encoder's z of the batch's windows (noise-free, with gradient)."""
LOG_STD_MIN, LOG_STD_MAX = -7.0, 2.0
ACTIVATIONS = {
    "leaky_relu": nn.LeakyReLU,
    "relu": nn.ReLU,
    "tanh": nn.Tanh,
    "elu": nn.ELU,
    "swish": nn.SiLU,
    "silu": nn.SiLU,
}


def mlp(sizes: list[int], activation: str) -> nn.Sequential:
    """Linear layers of `sizes` with `activation` between them (none after the last)."""
    if activation not in ACTIVATIONS:
        raise ValueError(
            f"fcnet_activation={activation!r} is not allowed for ESCP; expected one of "
            f"{tuple(ACTIVATIONS)}"
        )
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(ACTIVATIONS[activation]())
    return nn.Sequential(*layers)


class EscpTorchRLModule(
    TrainModeOnceMixin, TorchRLModule, TargetNetworkAPI, QNetAPI, InferenceOnlyAPI
):
    """π(a | s, z), Q(s, a, z) ×2 (+ targets) and the context encoder (module docstring)."""

    framework = "torch"
    disjoint_optimizer_losses = True
    """Each optimizer's loss reaches only its own parameters (critics: z̄ or z detached,
    targets without autograd; π: z detached, critics frozen, α detached; α: log π detached;
    encoder: RMDM only), so the Learner takes one backward pass of their sum."""

    def setup(self) -> None:
        if not isinstance(self.action_space, gym.spaces.Box):
            raise ValueError(f"ESCP needs a Box action space, got {self.action_space}")
        if not (
            isinstance(self.observation_space, gym.spaces.Box)
            and len(self.observation_space.shape) == 1
        ):
            raise ValueError(
                f"ESCP needs a flat Box observation space, got {self.observation_space}"
            )
        cfg = self.model_config or {}
        self.escp = EscpSettings.from_dict(cfg.get(ESCP_KEY))
        hiddens = list(cfg.get("fcnet_hiddens") or [128, 64])
        activation = cfg.get("fcnet_activation") or "leaky_relu"
        obs_dim = int(self.observation_space.shape[0])
        act_dim = int(self.action_space.shape[0])
        z = self.escp.context_dim
        self.twin_q = bool(cfg.get("twin_q", True))
        self.encoder = ContextEncoder(obs_dim + act_dim, z, self.escp.encoder_hidden)
        self.pi = mlp([obs_dim + z, *hiddens, 2 * act_dim], activation)
        if not self.inference_only:
            self.qf = mlp([obs_dim + z + act_dim, *hiddens, 1], activation)
            if self.twin_q:
                self.qf_twin = mlp([obs_dim + z + act_dim, *hiddens, 1], activation)
            t = self.escp.max_tasks
            self.register_buffer("task_means", torch.zeros(t, z))
            self.register_buffer("task_seen", torch.zeros(t, dtype=torch.bool))
            self.register_buffer("task_ids", torch.full((t,), -1, dtype=torch.long))

    # -- RLlib APIs ---------------------------------------------------------------------
    def get_initial_state(self) -> dict:
        return {}

    def get_non_inference_attributes(self) -> list[str]:
        out = ["qf", "target_qf", "task_means", "task_seen", "task_ids"]
        return out + (["qf_twin", "target_qf_twin"] if self.twin_q else [])

    def make_target_networks(self) -> None:
        self.target_qf = make_target_network(self.qf)
        if self.twin_q:
            self.target_qf_twin = make_target_network(self.qf_twin)

    def get_target_network_pairs(self) -> list[tuple[nn.Module, nn.Module]]:
        pairs = [(self.qf, self.target_qf)]
        return pairs + ([(self.qf_twin, self.target_qf_twin)] if self.twin_q else [])

    def forward_target(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        """min of the target critics at (s, a) with the critics' z (batch as
        `compute_q_values`)."""
        z = self.context(batch[WINDOW])
        z_q = self.critic_context(batch[DYNAMICS_ID], z)
        return {"q_target": self._q(batch[Columns.OBS], batch[Columns.ACTIONS], z_q, target=True)}

    def get_train_action_dist_cls(self) -> type:
        return _dist_cls(self.action_space)

    get_exploration_action_dist_cls = get_train_action_dist_cls
    get_inference_action_dist_cls = get_train_action_dist_cls

    # -- forward passes -----------------------------------------------------------------
    def context(self, window: torch.Tensor) -> torch.Tensor:
        """z of `window` [B, H, obs+act] (noise-free)."""
        return self.encoder(window)

    def policy_inputs(self, obs: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """π's distribution inputs (loc, log σ clipped to ESCP's [−7, 2]) for s ⊕ z."""
        loc, log_std = self.pi(torch.cat([obs, z], -1)).chunk(2, dim=-1)
        return torch.cat([loc, log_std.clamp(LOG_STD_MIN, LOG_STD_MAX)], -1)

    def _forward_inference(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        z = self.context(_window(batch, WINDOW))
        return {Columns.ACTION_DIST_INPUTS: self.policy_inputs(batch[Columns.OBS], z)}

    def _forward_exploration(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        z = add_context_noise(self.context(_window(batch, WINDOW)), self.escp.context_noise)
        return {Columns.ACTION_DIST_INPUTS: self.policy_inputs(batch[Columns.OBS], z)}

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        """SAC's quantities with ESCP's inputs (ESCP `SAC.sac_update`)."""
        noise = self.escp.context_noise
        # Without autograd while the encoder cannot step (the Learner says so: RMDM not yet
        # switched on, or rmdm_scale 0): the same z, no graph for the GRU.
        with torch.set_grad_enabled(self.__dict__.get("encoder_grad", True)):
            z = self.context(batch[WINDOW])
        with torch.no_grad():
            z_next = self.context(batch[NEXT_WINDOW])
        z_pi = add_context_noise(z.detach(), noise)
        z_pi_next = add_context_noise(z_next, noise)
        z_q = self.critic_context(batch[DYNAMICS_ID], z)
        return self.sac_outputs(batch, z, z_pi, z_pi_next, z_q)

    def sac_outputs(
        self,
        batch: dict[str, Any],
        context: torch.Tensor,
        z_pi: torch.Tensor,
        z_pi_next: torch.Tensor,
        z_q: torch.Tensor,
    ) -> dict[str, Any]:
        """SAC's training outputs with π reading `z_pi` (`z_pi_next` on the next states) and
        the critics `z_q`; `context` is returned as the `escp_context` output."""
        dist_cls = self.get_train_action_dist_cls()
        obs, next_obs, actions = batch[Columns.OBS], batch[Columns.NEXT_OBS], batch[Columns.ACTIONS]
        logits = self.policy_inputs(obs, z_pi)
        act_new, logp = dist_cls.from_logits(logits).rsample_and_logp()
        with torch.no_grad():
            logits_next = self.policy_inputs(next_obs, z_pi_next)
            act_next, logp_next = dist_cls.from_logits(logits_next).sample_and_logp()
            q_target_next = self._q(next_obs, act_next, z_q, target=True)
        out = {
            CONTEXT: context,
            Columns.ACTION_DIST_INPUTS: logits,
            "qf_preds": self._q_head(self.qf, obs, actions, z_q),
            "logp_resampled": logp,
            "logp_next_resampled": logp_next,
            "q_target_next": q_target_next,
        }
        if self.twin_q:
            out["qf_twin_preds"] = self._q_head(self.qf_twin, obs, actions, z_q)
        critics = [self.qf, self.qf_twin] if self.twin_q else [self.qf]
        params = [p for c in critics for p in c.parameters()]
        for p in params:  # Q's gradient reaches π only (RLlib's SAC module does the same)
            p.requires_grad_(False)
        try:
            out["q_curr"] = self._q(obs, act_new, z_q)
        finally:
            for p in params:
                p.requires_grad_(True)
        return out

    def critic_context(self, dynamics_id: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
        """The critics' z: each row's task moving average (detached); rows of tasks without
        one yet take the encoder's z (detached), as ESCP does before its first RMDM call."""
        slots = TaskSlots(self.task_ids).lookup(dynamics_id.reshape(-1).long(), add=False)
        known = slots >= 0
        known_slots = slots.clamp(min=0)
        has_mean = known & self.task_seen[known_slots]
        means = self.task_means[known_slots].to(z.dtype)
        return torch.where(has_mean.unsqueeze(-1), means, z.detach())

    @staticmethod
    def _q_head(net: nn.Module, obs: torch.Tensor, actions: torch.Tensor, z: torch.Tensor):
        return net(torch.cat([obs, z, actions], -1)).squeeze(-1)

    def _q(self, obs: torch.Tensor, actions: torch.Tensor, z: torch.Tensor, target: bool = False):
        nets = (
            (self.target_qf, getattr(self, "target_qf_twin", None))
            if target
            else (self.qf, getattr(self, "qf_twin", None))
        )
        q = self._q_head(nets[0], obs, actions, z)
        if self.twin_q:
            q = torch.min(q, self._q_head(nets[1], obs, actions, z))
        return q

    def compute_q_values(self, batch: dict[str, Any], squeeze: bool = True) -> torch.Tensor:
        """min of the twin critics at (s, a) with the critics' z (needs the batch's windows
        and `dynamics_id`)."""
        z = self.context(batch[WINDOW])
        return self._q(
            batch[Columns.OBS], batch[Columns.ACTIONS], self.critic_context(batch[DYNAMICS_ID], z)
        )

    def task_mean_context(self, dynamics_id: torch.Tensor, window: torch.Tensor) -> torch.Tensor:
        """The critics' z (`critic_context`) without running the encoder on rows whose task
        has a moving average: the encoder runs only on the other rows' windows."""
        slots = TaskSlots(self.task_ids).lookup(dynamics_id.reshape(-1).long(), add=False)
        has_mean = (slots >= 0) & self.task_seen[slots.clamp(min=0)]
        z_bar = self.task_means[slots.clamp(min=0)].to(window.dtype)
        if bool(has_mean.all()):  # one host sync per call
            return z_bar
        missing = (~has_mean).nonzero().squeeze(-1)
        z_bar = z_bar.clone()
        z_bar[missing] = self.context(window[missing]).detach()
        return z_bar

    def state_values(self, batch: dict[str, Any], context: str | None = None) -> torch.Tensor:
        """V(s) = min Q(s, π's deterministic action, z̄_task), for ASOR's ranking.

        π's z is the window's (`context="window"`, the default: what π acts on, one encoder
        pass over the batch) or the critics' z̄_task (`"task_mean"`: no encoder pass for rows
        whose task has a moving average; `value_context` sets the default)."""
        context = context or self.__dict__.get("value_context", "window")
        obs, window, ids = batch[Columns.OBS], batch[WINDOW], batch[DYNAMICS_ID]
        if context == "task_mean":
            z_q = z_pi = self.task_mean_context(ids, window)
        elif context == "window":
            z_pi = self.context(window)
            z_q = self.critic_context(ids, z_pi)
        else:
            raise ValueError(
                f"context={context!r} is not allowed; expected 'window' or 'task_mean'"
            )
        logits = self.policy_inputs(obs, z_pi)
        action = torch.tanh(logits.chunk(2, dim=-1)[0])  # ESCP's deterministic action
        return self._q(obs, action, z_q)


def _window(batch: dict[str, Any], key: str) -> torch.Tensor:
    window = batch.get(key)
    if window is None:
        raise ValueError(
            f"ESCP's module needs batch[{key!r}] (the last H steps of (s, a_prev)); build the "
            "config with rllib_asor.EscpConfig, which adds the env-to-module piece"
        )
    return window


class EscpSquashedGaussian(TorchSquashedGaussian):
    """RLlib's squashed Gaussian whose deterministic action is tanh(μ), as ESCP's
    (`Policy.rsample` returns `torch.tanh(mu)`); RLlib's returns the unsquashed μ."""

    def to_deterministic(self) -> TorchDeterministic:
        return TorchDeterministic(loc=compat.squash(self, self.loc))


def _dist_cls(action_space: gym.spaces.Box) -> type:
    """Squashed Gaussian in [−1, 1] (RLlib unsquashes to the env's bounds with
    `normalize_actions`, as for SAC)."""
    return EscpSquashedGaussian
