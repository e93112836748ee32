"""Random Network Distillation as a visitation-count proxy: c(s) = −‖f̂(s) − f(s)‖²."""

from __future__ import annotations

import contextlib
from collections.abc import Sequence

import torch
from torch import nn

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
