"""ASOR's auxiliary RLModules: the discriminator and the visitation-count proxy.

Both are `learner_only` (never built on env runners) and bring their own loss through
`SelfSupervisedLossAPI`, so any RLlib Learner trains them in its regular update. They take
flat float features that the ASOR connector piece prepares (`Columns.OBS` = the flattened,
key-selected observation), so they work for any observation space.

Running statistics (RND's observation normaliser, λ for `lambda_="auto"`) live in buffers:
they are part of the module state and survive checkpoint/restore.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis import SelfSupervisedLossAPI
from ray.rllib.core.rl_module.torch import TorchRLModule

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import Discriminator, discriminator_loss
from rllib_asor.asor.encoding import flat_dim, select_space
from rllib_asor.asor.ensemble import DynamicsEnsemble
from rllib_asor.asor.rnd import RND, PerDynamicsRND

LABEL = "asor_label"
ACTION_FEATURES = "asor_action"
DYNAMICS_ID = "asor_dynamics_id"


@contextlib.contextmanager
def _seeded(seed: int | None) -> Iterator[None]:
    """Initialise under `seed` without touching the process's global torch RNG stream."""
    if seed is None:
        yield
        return
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        yield


class _LearnerOnlyModule(TorchRLModule, SelfSupervisedLossAPI):
    """Shared set-up: the ASOR config and the feature size of the observation."""

    asor: AsorConfig

    def setup(self) -> None:
        self.asor = AsorConfig.from_dict(self.model_config["asor"])
        self.feature_dim = flat_dim(select_space(self.observation_space, self.asor.obs_keys))

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        raise NotImplementedError(f"{type(self).__name__} is learner-only: use forward_train")


class AsorDiscriminatorModule(_LearnerOnlyModule):
    """ω(s) = σ(f(s)); trained with the class-balanced GAN loss on D_P (1) vs D_Q (0)."""

    def setup(self) -> None:
        super().setup()
        with _seeded(self.asor.seed):
            self.disc = Discriminator(self.feature_dim, self.asor.disc_hiddens)
        init = self.asor.lambda_init if self.asor.lambda_ == "auto" else 0.0
        self.register_buffer("auto_lambda", torch.tensor(float(init)))

    def logits(self, features: torch.Tensor) -> torch.Tensor:
        """Discriminator logits for flat features [N, D] → [N]."""
        return self.disc(features)

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        return {"logits": self.disc(batch[Columns.OBS])}

    def compute_self_supervised_loss(
        self, *, learner: Any, module_id: str, config: Any, batch: dict, fwd_out: dict, **kw: Any
    ) -> torch.Tensor:
        loss, stats = discriminator_loss(fwd_out["logits"], batch[LABEL], self.asor.label_smoothing)
        learner.metrics.log_dict({k: v.item() for k, v in stats.items()}, key=module_id, window=1)
        return loss


class AsorProxyModule(_LearnerOnlyModule):
    """The visitation-count proxy c(s): RND (`proxy="rnd"`) or a dynamics ensemble."""

    def setup(self) -> None:
        super().setup()
        seed = None if self.asor.seed is None else self.asor.seed + 1
        with _seeded(seed):
            if self.asor.proxy == "rnd":
                self.rnd = RND(
                    self.feature_dim, self.asor.rnd_hiddens, self.asor.rnd_embedding_dim, seed
                )
            elif self.asor.proxy == "rnd_per_dynamics":
                self.rnd = PerDynamicsRND(
                    self.feature_dim,
                    self.asor.rnd_hiddens,
                    self.asor.rnd_embedding_dim,
                    self.asor.dynamics_buckets,
                    seed,
                )
            else:
                self.ensemble = DynamicsEnsemble(
                    self.feature_dim,
                    flat_dim(self.action_space),
                    self.asor.ensemble_size,
                    self.asor.rnd_hiddens,
                )

    @torch.no_grad()
    def update_and_count(
        self,
        features: torch.Tensor,
        actions: torch.Tensor | None = None,
        next_features: torch.Tensor | None = None,
        dynamics_ids: torch.Tensor | None = None,
    ) -> torch.Tensor:
        """Fold the batch into the normalisers, then return c(s) (higher = visited more)."""
        if self.asor.proxy == "rnd":
            self.rnd.update_normalizer(features)
            return self.rnd.count_proxy(features)
        if self.asor.proxy == "rnd_per_dynamics":
            self.rnd.update(features, dynamics_ids)
            return self.rnd.count_proxy(features)
        self.ensemble.update_normalizers(features, next_features)
        return self.ensemble.count_proxy(features, actions)

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        if self.asor.proxy == "rnd":
            return {"rnd_error": self.rnd.prediction_error(batch[Columns.OBS])}
        if self.asor.proxy == "rnd_per_dynamics":
            return {"rnd_error": self.rnd.prediction_error(batch[Columns.OBS], batch[DYNAMICS_ID])}
        return {
            "ensemble_loss": self.ensemble.loss(
                batch[Columns.OBS], batch[ACTION_FEATURES], batch[Columns.NEXT_OBS]
            )
        }

    def compute_self_supervised_loss(
        self, *, learner: Any, module_id: str, config: Any, batch: dict, fwd_out: dict, **kw: Any
    ) -> torch.Tensor:
        if "rnd_error" in fwd_out:
            loss = fwd_out["rnd_error"].mean()
            learner.metrics.log_value((module_id, "rnd_loss"), loss.item(), window=1)
        else:
            loss = fwd_out["ensemble_loss"]
            learner.metrics.log_value((module_id, "ensemble_loss"), loss.item(), window=1)
        return loss
