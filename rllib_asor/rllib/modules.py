"""ASOR's auxiliary RLModules: the discriminator and the visitation-count proxy.

Both are `learner_only` (never built on env runners) and bring their own loss through
`SelfSupervisedLossAPI`, so any RLlib Learner trains them in its regular update. They take
flat float features that the ASOR connector piece prepares (`Columns.OBS` = the flattened,
key-selected observation), so they work for any observation space.

Running statistics (normalisers, the archive, λ for `lambda_="auto"`) live in buffers: they
are part of the module state and survive checkpoint/restore.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

import torch
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.apis import SelfSupervisedLossAPI
from ray.rllib.core.rl_module.torch import TorchRLModule

from rllib_asor.algorithms.common.asor_adapter import DYNAMICS_ID
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import Discriminator, discriminator_loss
from rllib_asor.asor.networks import flat_dim, select_space
from rllib_asor.asor.proxy import ProxyInputs, make_proxy
from rllib_asor.asor.update import AsorState

LABEL = "asor_label"
ACTION_FEATURES = "asor_action"


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
    disjoint_optimizer_losses = True
    """One optimizer whose loss reaches only this module's parameters (the RND target is
    frozen): the fast off-policy Learner steps it with one backward pass, as its SAC modules."""

    def setup(self) -> None:
        self.asor = AsorConfig.from_dict(self.model_config["asor"])
        self.feature_dim = flat_dim(select_space(self.observation_space, self.asor.obs_keys))

    def _forward(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        raise NotImplementedError(f"{type(self).__name__} is learner-only: use forward_train")

    def get_state(self, *args: Any, inference_only: bool = False, **kwargs: Any) -> dict:
        """The module's state; empty with `inference_only`. RLlib asks for the inference-only
        state only to send it to env runners (the weight sync after every update, restores),
        and it asks for every module the update reported, these included, although runners
        never hold a learner-only module and drop its state: on the race that was the
        discriminator's archive, about 12 MB copied off the Learner's device, serialised and
        shipped to every runner each iteration. Checkpoints and Learner-to-Learner state
        (`inference_only=False`) keep everything."""
        if inference_only:
            return {}
        return super().get_state(*args, inference_only=False, **kwargs)


class AsorDiscriminatorModule(_LearnerOnlyModule):
    """ω(s) = σ(f(s)) and the rest of ASOR's state (`rllib_asor.asor.update.AsorState`:
    normalisers, archive, λ); trained with the class-balanced GAN loss on D_P (1) vs D_Q (0)
    plus the gradient penalty and logit regularisation."""

    def setup(self) -> None:
        super().setup()
        with _seeded(self.asor.seed):
            self.state = AsorState(self.asor, self.feature_dim)

    @property
    def disc(self) -> Discriminator:
        """The discriminator network."""
        return self.state.disc

    def logits(self, features: torch.Tensor) -> torch.Tensor:
        """Discriminator logits for flat features [N, D] → [N]."""
        return self.state.disc(features)

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        return {"logits": self.state.disc(batch[Columns.OBS])}

    def compute_self_supervised_loss(
        self, *, learner: Any, module_id: str, config: Any, batch: dict, fwd_out: dict, **kw: Any
    ) -> torch.Tensor:
        labels = batch[LABEL]
        loss, stats = discriminator_loss(fwd_out["logits"], labels, self.asor.label_smoothing)
        reg, reg_stats = self.state.disc.regularizer(
            batch[Columns.OBS][labels > 0.5], self.asor.disc_grad_penalty, self.asor.disc_logit_reg
        )
        stats = {**stats, **reg_stats}
        learner.metrics.log_dict({k: v.item() for k, v in stats.items()}, key=module_id, window=1)
        return loss + reg


class AsorProxyModule(_LearnerOnlyModule):
    """The visitation-count proxy c(s) (`rllib_asor.asor.proxy`: rnd, ensemble,
    rnd_per_dynamics), trained on the proxy batch the connector writes."""

    def setup(self) -> None:
        super().setup()
        seed = None if self.asor.seed is None else self.asor.seed + 1
        with _seeded(seed):
            self.proxy = make_proxy(self.asor, self.feature_dim, flat_dim(self.action_space), seed)

    def _forward_train(self, batch: dict[str, Any], **kwargs: Any) -> dict[str, Any]:
        return {"proxy_loss": self.proxy.loss(proxy_inputs(batch))}

    def compute_self_supervised_loss(
        self, *, learner: Any, module_id: str, config: Any, batch: dict, fwd_out: dict, **kw: Any
    ) -> torch.Tensor:
        loss = fwd_out["proxy_loss"]
        name = "ensemble_loss" if self.asor.proxy == "ensemble" else "rnd_loss"
        learner.metrics.log_value((module_id, name), loss.item(), window=1)
        return loss


def proxy_batch(x: ProxyInputs) -> dict[str, torch.Tensor]:
    """The proxy module's train batch for `x` (the inverse of `proxy_inputs`)."""
    out = {Columns.OBS: x.features}
    for key, value in (
        (ACTION_FEATURES, x.actions),
        (Columns.NEXT_OBS, x.next_features),
        (DYNAMICS_ID, x.dynamics_ids),
    ):
        if value is not None:
            out[key] = value
    return out


def proxy_inputs(batch: dict[str, Any]) -> ProxyInputs:
    """`ProxyInputs` from a proxy train batch."""
    return ProxyInputs(
        batch[Columns.OBS],
        batch.get(ACTION_FEATURES),
        batch.get(Columns.NEXT_OBS),
        batch.get(DYNAMICS_ID),
    )
