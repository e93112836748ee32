"""The inverse dynamics model p(a | s, s′) of BCO and SOIL, its losses and its trainer.

`InverseDynamicsModel`: an MLP over [s, s′] (tanh hidden layers, the last layer's weights
scaled by 0.01, as SOIL's `InvDynMLP`). Discrete actions: logits, cross-entropy, the inferred
action is the argmax (BCO's discrete form). Box actions: the mean action, squared error (SOIL's
`MSELoss`, a Gaussian of fixed variance), the inferred action that mean clipped to the box.

`IdmTrainer` owns the model, its Adam and a FIFO buffer of the learner's own (s, a, s′);
`add(...)` appends transitions, `update()` takes `steps` Adam steps on random minibatches of the
buffer (SOIL's `train_from_paths`, BCO's model learning), `infer(s, s′)` labels expert
transitions. With several Learners (DDP) the gradients are averaged over all of them, so every
copy stays the same. Its state (checkpoints) holds the model, the optimizer, the buffer and rng.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
import torch
import torch.distributed as dist
from torch import nn
from torch.nn import functional as F


def idm_loss(prediction: torch.Tensor, actions: torch.Tensor, discrete: bool) -> torch.Tensor:
    """Mean cross-entropy of integer `actions` under logits `prediction` [N, n] (discrete), or
    mean squared error of `actions` [N, A] against `prediction` [N, A], over rows and
    dimensions (torch's `MSELoss`)."""
    if discrete:
        return F.cross_entropy(prediction, actions.long().reshape(-1))
    return F.mse_loss(prediction, actions.reshape(prediction.shape).to(prediction.dtype))


def imitation_loss(logp: torch.Tensor, weight: float | torch.Tensor = 1.0) -> torch.Tensor:
    """weight · the mean negative log-likelihood of the inferred actions (`logp` [N]):
    behavioural cloning's loss, SOIL's auxiliary term."""
    return -weight * logp.mean()


class InverseDynamicsModel(nn.Module):
    """p(a | s, s′) as an MLP over the concatenated flat observations (module docstring)."""

    def __init__(
        self, obs_dim: int, action_space: gym.Space, hiddens: Sequence[int] = (64, 64)
    ) -> None:
        super().__init__()
        self.discrete = isinstance(action_space, gym.spaces.Discrete)
        if self.discrete:
            out = int(action_space.n)
            low = high = torch.zeros(0)
        elif isinstance(action_space, gym.spaces.Box):
            out = int(np.prod(action_space.shape))
            low = torch.as_tensor(action_space.low, dtype=torch.float32).reshape(-1)
            high = torch.as_tensor(action_space.high, dtype=torch.float32).reshape(-1)
        else:
            raise ValueError(
                f"inverse dynamics model: action space {action_space} is not supported; "
                "allowed: Discrete or Box"
            )
        layers: list[nn.Module] = []
        width = 2 * obs_dim
        for h in hiddens:
            layers += [nn.Linear(width, h), nn.Tanh()]
            width = h
        last = nn.Linear(width, out)
        with torch.no_grad():
            last.weight.mul_(1e-2)
            last.bias.mul_(1e-2)
        self.net = nn.Sequential(*layers, last)
        self.register_buffer("low", low)
        self.register_buffer("high", high)

    def forward(self, obs: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
        """Logits (discrete) or mean action (Box) per row."""
        x = torch.cat([obs.flatten(1), next_obs.flatten(1)], dim=-1).float()
        return self.net(x)

    def loss(
        self, obs: torch.Tensor, next_obs: torch.Tensor, actions: torch.Tensor
    ) -> torch.Tensor:
        return idm_loss(self(obs, next_obs), actions, self.discrete)

    @torch.no_grad()
    def infer(self, obs: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
        """The inferred action of each row: argmax (discrete, int64) or the clipped mean."""
        pred = self(obs, next_obs)
        if self.discrete:
            return pred.argmax(-1)
        low, high = self.low.to(pred.device), self.high.to(pred.device)
        return torch.maximum(torch.minimum(pred, high), low)


class IdmTrainer:
    """An `InverseDynamicsModel`, its Adam and a FIFO buffer of (s, a, s′) (module docstring)."""

    def __init__(
        self,
        obs_dim: int,
        action_space: gym.Space,
        *,
        hiddens: Sequence[int] = (64, 64),
        lr: float = 1e-3,
        steps: int = 500,
        batch_size: int = 32,
        capacity: int = 1_000_000,
        seed: int = 0,
        device: Any = "cpu",
    ) -> None:
        self.device = torch.device(device)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)  # the same initial weights on every Learner
            self.model = InverseDynamicsModel(obs_dim, action_space, hiddens).to(self.device)
        self.optim = torch.optim.Adam(self.model.parameters(), lr=lr)
        self.steps, self.batch_size, self.capacity = steps, batch_size, capacity
        act_dim = 1 if self.model.discrete else int(np.prod(action_space.shape))
        self._obs = np.zeros((0, obs_dim), np.float32)
        self._next = np.zeros((0, obs_dim), np.float32)
        self._act = np.zeros((0, act_dim), np.float32)
        self._rng = np.random.default_rng(seed)

    def __len__(self) -> int:
        return len(self._obs)

    def add(self, obs: Any, actions: Any, next_obs: Any) -> None:
        """Append transitions (arrays or tensors); the oldest go beyond `capacity`."""
        n = len(obs)
        if n == 0:
            return

        def flat(x: Any, width: int) -> np.ndarray:
            x = x.detach().cpu().numpy() if isinstance(x, torch.Tensor) else np.asarray(x)
            return x.reshape(n, width).astype(np.float32)

        self._obs = np.concatenate([self._obs, flat(obs, self._obs.shape[1])])[-self.capacity :]
        self._next = np.concatenate([self._next, flat(next_obs, self._next.shape[1])])[
            -self.capacity :
        ]
        self._act = np.concatenate([self._act, flat(actions, self._act.shape[1])])[-self.capacity :]

    def update(self, steps: int | None = None) -> dict[str, float]:
        """`steps` (default: the trainer's) Adam steps on random minibatches of the buffer; the
        mean loss and, for discrete actions, the accuracy of the last minibatch."""
        if len(self) == 0:
            return {}
        total = 0.0
        n = steps if steps is not None else self.steps
        with torch.enable_grad():
            for _ in range(n):
                idx = self._rng.integers(0, len(self), min(self.batch_size, len(self)))
                obs, act, nxt = (
                    torch.as_tensor(a[idx], device=self.device)
                    for a in (self._obs, self._act, self._next)
                )
                pred = self.model(obs, nxt)
                loss = idm_loss(pred, act, self.model.discrete)
                self.optim.zero_grad(set_to_none=False)
                loss.backward()
                _average_gradients(self.model)
                self.optim.step()
                total += float(loss.detach())
        stats = {"idm_loss": total / max(n, 1), "idm_rows": float(len(self))}
        if self.model.discrete:
            stats["idm_accuracy"] = float(
                (pred.argmax(-1) == act.long().reshape(-1)).float().mean()
            )
        return stats

    def infer(self, obs: Any, next_obs: Any, chunk: int = 65536) -> torch.Tensor:
        """Inferred actions of transitions (s, s′), computed in chunks, on the trainer's device."""
        obs = torch.as_tensor(obs, device=self.device)
        next_obs = torch.as_tensor(next_obs, device=self.device)
        parts = [
            self.model.infer(obs[i : i + chunk], next_obs[i : i + chunk])
            for i in range(0, len(obs), chunk)
        ]
        return torch.cat(parts) if parts else torch.zeros(0, device=self.device)

    def get_state(self) -> dict[str, Any]:
        return {
            "model": {k: v.detach().cpu() for k, v in self.model.state_dict().items()},
            "optim": self.optim.state_dict(),
            "buffer": {"obs": self._obs, "act": self._act, "next": self._next},
            "rng": self._rng.bit_generator.state,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        self.model.load_state_dict({k: v.to(self.device) for k, v in state["model"].items()})
        self.optim.load_state_dict(state["optim"])
        buf = state["buffer"]
        self._obs, self._act, self._next = buf["obs"], buf["act"], buf["next"]
        self._rng.bit_generator.state = state["rng"]


def _average_gradients(module: nn.Module) -> None:
    """Mean of each gradient over the Learners' process group (no-op with one Learner)."""
    if not (dist.is_available() and dist.is_initialized()) or dist.get_world_size() == 1:
        return
    size = dist.get_world_size()
    for p in module.parameters():
        if p.grad is not None:
            dist.all_reduce(p.grad)
            p.grad /= size
