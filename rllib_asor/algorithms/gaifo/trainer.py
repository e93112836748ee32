"""GAIfO's discriminator, its Adam and the expert rows, owned by the Learner.

`reward(features)` scores policy transitions (no gradient); `update(features)` takes
`disc_steps` Adam steps on random policy rows against as many random expert rows. With several
Learners (DDP) the gradients are averaged over all of them, so every copy stays the same.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import torch
import torch.distributed as dist

from rllib_asor.algorithms.common.demonstrations import Demonstrations
from rllib_asor.algorithms.gaifo.discriminator import TransitionDiscriminator
from rllib_asor.algorithms.gaifo.reward import gaifo_loss, imitation_reward, transition_features
from rllib_asor.algorithms.gaifo.settings import GaifoSettings


class GaifoTrainer:
    """D(s, s′) (or what `disc_input` names) with its optimizer and the expert transitions
    (module docstring); with `input_norm` the inputs are normalised by the expert rows' mean
    and std, or with `input_norm_rows: round` by those of each update's expert and policy rows."""

    def __init__(
        self, settings: GaifoSettings, demos: Demonstrations, device: Any = "cpu", rank: int = 0
    ) -> None:
        self.settings = settings
        self.device = torch.device(device)
        self.expert = transition_features(
            torch.as_tensor(demos.obs, device=self.device),
            torch.as_tensor(demos.next_obs, device=self.device),
            settings.state_dims,
            settings.disc_input,
        ).to(self.device)
        self.disc = TransitionDiscriminator(self.expert.shape[1], settings.disc_hiddens).to(
            self.device
        )
        if settings.input_norm:
            self.disc.fit_normalizer(self.expert)  # once: the same on every Learner
        self.optim = torch.optim.Adam(self.disc.parameters(), lr=settings.disc_lr)
        self._rng = np.random.default_rng(settings.seed + 1000 * rank)

    def features(self, obs: torch.Tensor, next_obs: torch.Tensor) -> torch.Tensor:
        s = self.settings
        return transition_features(obs, next_obs, s.state_dims, s.disc_input).to(self.device)

    @torch.no_grad()
    def reward(self, features: torch.Tensor) -> torch.Tensor:
        """reward_scale · the imitation reward of each row (the discriminator as it is now)."""
        s = self.settings
        return s.reward_scale * imitation_reward(self.disc(features), s.reward_form)

    def update(self, features: torch.Tensor) -> dict[str, torch.Tensor]:
        """`disc_steps` steps on policy rows `features` against expert rows; the last
        step's statistics."""
        s = self.settings
        if s.input_norm and s.input_norm_rows == "round":
            self._fit_round_normalizer(features)
        stats: dict[str, torch.Tensor] = {}
        with torch.enable_grad():
            for _ in range(s.disc_steps):
                n = min(s.disc_batch_size, max(features.shape[0], 1))
                fake = features[self._pick(features.shape[0], n)]
                real = self.expert[self._pick(self.expert.shape[0], n)]
                loss, stats = gaifo_loss(self.disc(real), self.disc(fake))
                if s.grad_penalty > 0:
                    gp = self.disc.gradient_penalty(real, fake, s.grad_penalty_form)
                    loss = loss + s.grad_penalty * gp
                    stats = {**stats, "disc_grad_penalty": gp.detach()}
                self.optim.zero_grad(set_to_none=False)
                loss.backward()
                _average_gradients(self.disc)
                self.optim.step()
        return stats

    def _fit_round_normalizer(self, features: torch.Tensor) -> None:
        """Mean and std of the expert rows and the policy rows `features` of every Learner (the
        expert rows counted once: each Learner holds all of them), so every copy of D stays the
        same."""
        f = features.double()
        local = torch.stack([f.sum(0), (f * f).sum(0)])
        count = torch.tensor([float(f.shape[0])], dtype=torch.float64, device=f.device)
        if dist.is_available() and dist.is_initialized() and dist.get_world_size() > 1:
            dist.all_reduce(local)
            dist.all_reduce(count)
        e = self.expert.double()
        n = count[0] + e.shape[0]
        mean = (local[0] + e.sum(0)) / n
        var = ((local[1] + (e * e).sum(0)) / n - mean * mean).clamp_min(0.0)
        self.disc.mean.copy_(mean.float())
        self.disc.std.copy_(var.sqrt().float().clamp_min(1e-4))

    def _pick(self, size: int, n: int) -> torch.Tensor:
        if size == 0:
            return torch.zeros(0, dtype=torch.long, device=self.device)
        return torch.as_tensor(self._rng.integers(0, size, n), device=self.device)

    def get_state(self) -> dict[str, Any]:
        """The discriminator (with its normaliser), its optimizer and the sampling rng."""
        return {
            "disc": {k: v.detach().cpu() for k, v in self.disc.state_dict().items()},
            "optim": self.optim.state_dict(),
            "rng": self._rng.bit_generator.state,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        self.disc.load_state_dict({k: v.to(self.device) for k, v in state["disc"].items()})
        self.optim.load_state_dict(state["optim"])
        self._rng.bit_generator.state = state["rng"]


def _average_gradients(module: torch.nn.Module) -> None:
    """Mean of each gradient over the Learners' process group (no-op with one Learner)."""
    if not (dist.is_available() and dist.is_initialized()) or dist.get_world_size() == 1:
        return
    size = dist.get_world_size()
    for p in module.parameters():
        if p.grad is not None:
            dist.all_reduce(p.grad)
            p.grad /= size
