"""Step 2: the visitation-count proxy c(s), one interface for every kind, and the kinds.

A `VisitationProxy` is an `nn.Module` with three methods:
- `observe(x)`  folds a batch into its running statistics (no gradient),
- `count(x)`    c per state, higher = visited more (no gradient),
- `loss(x)`     the training loss of its predictor(s), a scalar.
`x` is a `ProxyInputs`: the flat features plus what some proxies need (actions and next
features for the dynamics ensemble, dynamics ids for the per-dynamics RND).

The predictors: Random Network Distillation, c(s) = −‖f̂(s) − f(s)‖² (`RND`, and
`PerDynamicsRND`: one predictor per dynamics, c the count under the least familiar one); and
ensemble disagreement, c(s, a) = −max_k ‖μ_k − mean_k μ‖, K dynamics models predicting the
normalised change s_{t+1} − s_t from (s_t, a_t): where they agree the region has been seen
often, disagreement is high on rarely visited states (`DynamicsEnsemble`).
"""

from __future__ import annotations

import contextlib
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch import nn

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.networks import RunningMeanStd, mlp


def _target_and_predictors(
    in_dim: int, hiddens: Sequence[int], embedding_dim: int, count: int, seed: int | None
) -> tuple[nn.Module, list[nn.Module]]:
    """A frozen random target and `count` predictors; with a seed, drawn from it without
    disturbing the global torch RNG stream."""
    with torch.random.fork_rng() if seed is not None else contextlib.nullcontext():
        if seed is not None:
            torch.manual_seed(seed)
        target = mlp(in_dim, hiddens, embedding_dim)
        predictors = [mlp(in_dim, hiddens, embedding_dim) for _ in range(count)]
    for p in target.parameters():
        p.requires_grad_(False)
    return target, predictors


class RND(nn.Module):
    """Frozen random target f, trained predictor f̂, running input normalisation (clip ±5).

    The target's parameters have `requires_grad=False`; optimisers must skip them.
    """

    def __init__(
        self,
        in_dim: int,
        hiddens: Sequence[int] = (128, 128),
        embedding_dim: int = 64,
        seed: int | None = None,
    ) -> None:
        super().__init__()
        self.target, (self.predictor,) = _target_and_predictors(
            in_dim, hiddens, embedding_dim, 1, seed
        )
        self.obs_rms = RunningMeanStd(in_dim)

    def prediction_error(self, x: torch.Tensor) -> torch.Tensor:
        """Per-sample mean squared error between predictor and target, shape [N]."""
        z = self.obs_rms.normalize(x)
        with torch.no_grad():
            target = self.target(z)
        return (self.predictor(z) - target).pow(2).mean(-1)

    @torch.no_grad()
    def count_proxy(self, x: torch.Tensor) -> torch.Tensor:
        """Higher = visited more: −prediction error, shape [N]."""
        return -self.prediction_error(x)

    def update_normalizer(self, x: torch.Tensor) -> None:
        """Fold a batch of raw inputs into the running mean/std."""
        self.obs_rms.update(x)


class PerDynamicsRND(nn.Module):
    """RND that counts visits per dynamics: one predictor per dynamics bucket, one frozen target.

    c(s) is the count under the *least familiar* dynamics seen so far, −max_k ‖f̂_k(s) − f(s)‖²,
    so it is high only for states visited under every dynamics — the paper's "globally
    accessible" states — instead of states the current policy visits often overall
    (docs/results.md, lava world). Our extension; needs the env's dynamics id per step.
    """

    def __init__(
        self,
        in_dim: int,
        hiddens: Sequence[int] = (128, 128),
        embedding_dim: int = 64,
        buckets: int = 8,
        seed: int | None = None,
    ) -> None:
        super().__init__()
        self.target, predictors = _target_and_predictors(
            in_dim, hiddens, embedding_dim, buckets, seed
        )
        self.predictors = nn.ModuleList(predictors)
        self.obs_rms = RunningMeanStd(in_dim)
        self.register_buffer("seen", torch.zeros(buckets))

    @property
    def buckets(self) -> int:
        """Number of dynamics buckets (dynamics ids are taken modulo this)."""
        return len(self.predictors)

    def bucket_of(self, dynamics_ids: torch.Tensor) -> torch.Tensor:
        """Bucket index of each dynamics id."""
        return torch.remainder(dynamics_ids.long(), self.buckets)

    def errors(self, x: torch.Tensor) -> torch.Tensor:
        """Squared error of every bucket's predictor, shape [K, N]."""
        z = self.obs_rms.normalize(x)
        with torch.no_grad():
            target = self.target(z)
        return torch.stack([(p(z) - target).pow(2).mean(-1) for p in self.predictors])

    def prediction_error(self, x: torch.Tensor, dynamics_ids: torch.Tensor) -> torch.Tensor:
        """Each state's error under its own dynamics' predictor (the training loss), [N]."""
        errors = self.errors(x)
        return errors.gather(0, self.bucket_of(dynamics_ids).unsqueeze(0)).squeeze(0)

    @torch.no_grad()
    def count_proxy(self, x: torch.Tensor) -> torch.Tensor:
        """−max over the dynamics seen so far of the error, shape [N]."""
        errors = self.errors(x)
        seen = self.seen > 0
        if not seen.any():
            return -errors.mean(0)
        return -errors[seen].max(0).values

    def update(self, x: torch.Tensor, dynamics_ids: torch.Tensor) -> None:
        """Fold a batch into the normaliser and mark its dynamics as seen."""
        self.obs_rms.update(x)
        self.seen[self.bucket_of(dynamics_ids).unique()] = 1.0


class DynamicsEnsemble(nn.Module):
    """K independent MLP dynamics models with shared input/target normalisers."""

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        size: int = 5,
        hiddens: Sequence[int] = (128, 128),
    ) -> None:
        super().__init__()
        self.models = nn.ModuleList(
            mlp(obs_dim + action_dim, hiddens, obs_dim) for _ in range(size)
        )
        self.obs_rms = RunningMeanStd(obs_dim)
        self.delta_rms = RunningMeanStd(obs_dim)

    def predictions(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Normalised predicted deltas, shape [K, N, obs_dim]."""
        x = torch.cat([self.obs_rms.normalize(obs), actions.float()], dim=-1)
        return torch.stack([m(x) for m in self.models])

    def loss(
        self, obs: torch.Tensor, actions: torch.Tensor, next_obs: torch.Tensor
    ) -> torch.Tensor:
        """Sum over models of the MSE to the normalised true delta."""
        target = self.delta_rms.normalize(next_obs - obs)
        return (self.predictions(obs, actions) - target.unsqueeze(0)).pow(2).mean(dim=(1, 2)).sum()

    @torch.no_grad()
    def disagreement(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """u = max_k ‖μ_k − mean_k μ‖, shape [N]."""
        preds = self.predictions(obs, actions)
        return (preds - preds.mean(0, keepdim=True)).norm(dim=-1).max(0).values

    @torch.no_grad()
    def count_proxy(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        """Higher = visited more: −disagreement, shape [N]."""
        return -self.disagreement(obs, actions)

    def update_normalizers(self, obs: torch.Tensor, next_obs: torch.Tensor) -> None:
        """Fold a batch of transitions into the input and target statistics."""
        self.obs_rms.update(obs)
        self.delta_rms.update(next_obs - obs)


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
