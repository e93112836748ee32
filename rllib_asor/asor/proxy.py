"""Step 2: the visitation-count proxy c(s), one interface for every kind.

A `VisitationProxy` is an `nn.Module` with three methods:
- `observe(x)`  folds a batch into its running statistics (no gradient),
- `count(x)`    c per state, higher = visited more (no gradient),
- `loss(x)`     the training loss of its predictor(s), a scalar.
`x` is a `ProxyInputs`: the flat features plus what some proxies need (actions and next
features for the dynamics ensemble, dynamics ids for the per-dynamics RND).
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
from torch import nn

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.ensemble import DynamicsEnsemble
from rllib_asor.asor.rnd import RND, PerDynamicsRND


@dataclass
class ProxyInputs:
    """What a proxy sees for N states."""

    features: torch.Tensor
    actions: torch.Tensor | None = None
    next_features: torch.Tensor | None = None
    dynamics_ids: torch.Tensor | None = None

    def require(self, name: str, proxy: str) -> torch.Tensor:
        """The field `name`, or a ValueError saying which proxy needed it."""
        value = getattr(self, name)
        if value is None:
            raise ValueError(f"asor.proxy={proxy!r} needs {name}; none were given")
        return value


class VisitationProxy(nn.Module):
    """observe / count / loss (see the module docstring)."""

    name = ""

    def observe(self, x: ProxyInputs) -> None:  # pragma: no cover - interface
        raise NotImplementedError

    def count(self, x: ProxyInputs) -> torch.Tensor:  # pragma: no cover - interface
        raise NotImplementedError

    def loss(self, x: ProxyInputs) -> torch.Tensor:  # pragma: no cover - interface
        raise NotImplementedError


class RndProxy(VisitationProxy):
    """c(s) = −‖f̂(s) − f(s)‖² (Random Network Distillation)."""

    name = "rnd"

    def __init__(self, rnd: RND) -> None:
        super().__init__()
        self.rnd = rnd

    @torch.no_grad()
    def observe(self, x: ProxyInputs) -> None:
        self.rnd.update_normalizer(x.features)

    def count(self, x: ProxyInputs) -> torch.Tensor:
        return self.rnd.count_proxy(x.features)

    def loss(self, x: ProxyInputs) -> torch.Tensor:
        return self.rnd.prediction_error(x.features).mean()


class PerDynamicsRndProxy(VisitationProxy):
    """c(s) = the RND count under the least familiar dynamics seen so far."""

    name = "rnd_per_dynamics"

    def __init__(self, rnd: PerDynamicsRND) -> None:
        super().__init__()
        self.rnd = rnd

    @torch.no_grad()
    def observe(self, x: ProxyInputs) -> None:
        self.rnd.update(x.features, x.require("dynamics_ids", self.name))

    def count(self, x: ProxyInputs) -> torch.Tensor:
        return self.rnd.count_proxy(x.features)

    def loss(self, x: ProxyInputs) -> torch.Tensor:
        return self.rnd.prediction_error(x.features, x.require("dynamics_ids", self.name)).mean()


class EnsembleProxy(VisitationProxy):
    """c(s, a) = −max_k ‖μ_k − mean μ‖ (disagreement of K dynamics models)."""

    name = "ensemble"

    def __init__(self, ensemble: DynamicsEnsemble) -> None:
        super().__init__()
        self.ensemble = ensemble

    @torch.no_grad()
    def observe(self, x: ProxyInputs) -> None:
        self.ensemble.update_normalizers(x.features, x.require("next_features", self.name))

    def count(self, x: ProxyInputs) -> torch.Tensor:
        return self.ensemble.count_proxy(x.features, x.require("actions", self.name))

    def loss(self, x: ProxyInputs) -> torch.Tensor:
        return self.ensemble.loss(
            x.features, x.require("actions", self.name), x.require("next_features", self.name)
        )


def make_proxy(
    cfg: AsorConfig, feature_dim: int, action_dim: int, seed: int | None
) -> VisitationProxy:
    """The proxy `cfg.proxy` names, initialised from `seed` (None: the global RNG)."""
    if cfg.proxy == "rnd":
        return RndProxy(RND(feature_dim, cfg.rnd_hiddens, cfg.rnd_embedding_dim, seed))
    if cfg.proxy == "rnd_per_dynamics":
        return PerDynamicsRndProxy(
            PerDynamicsRND(
                feature_dim, cfg.rnd_hiddens, cfg.rnd_embedding_dim, cfg.dynamics_buckets, seed
            )
        )
    return EnsembleProxy(
        DynamicsEnsemble(feature_dim, action_dim, cfg.ensemble_size, cfg.rnd_hiddens)
    )
