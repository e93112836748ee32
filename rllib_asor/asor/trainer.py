"""`AsorTrainer`: ASOR's networks and their training for one policy, in one call per train batch.

Plain torch, no Ray. `step(batch)` runs the paper's steps 1-7 (`rank`, i.e. `asor_update`:
D_P, Δr from ω before this update, λ), then trains (`learn`) the discriminator on D_P (1) vs D_Q (0) and the
visitation proxy on the batch's states, each with its own Adam optimiser, for `aux_epochs`
passes over its batch (one when unset) in minibatches of the caller's size, and returns Δr and
the metrics of both. The caller adds Δr to its rewards; nothing of it enters the policy's
minibatch loop.

Everything the trainer keeps (networks, running statistics, archive, λ, the optimisers'
moments and its random streams) is in `get_state()`; `set_state` restores it on the device the
trainer is on, whichever device wrote it.

Several Learners (torch.distributed initialised): every rank calls `step` with the same whole
batch (the rows of all ranks), so the ranking and Δr are the same everywhere; each rank trains
on its own equal share of the aux batches and the gradients are averaged over the ranks before
every optimiser step, so every rank keeps the same ASOR state.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Iterator
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
from torch import nn

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.proxy import ProxyInputs, make_proxy
from rllib_asor.asor.update import (
    AsorBatch,
    AsorResult,
    AsorState,
    asor_update,
    ranked_proxy_inputs,
)

STATE_FORMAT = 2
"""Version of `get_state()`'s layout; a state without it (or with another) is refused."""


class AsorTrainer(nn.Module):
    """ASOR for one policy: `state` (discriminator, normalisers, archive, λ), `proxy` (None in
    modes that need none) and their optimisers; see the module docstring."""

    def __init__(
        self, cfg: AsorConfig, feature_dim: int, action_dim: int, seed: int | None = None
    ) -> None:
        super().__init__()
        self.cfg = cfg
        with _seeded(seed):
            self.state = AsorState(cfg, feature_dim)
        proxy_seed = None if seed is None else seed + 1
        self.proxy = None
        if cfg.needs_proxy:
            with _seeded(proxy_seed):
                self.proxy = make_proxy(cfg, feature_dim, action_dim, proxy_seed)
        disc_params = [p for p in self.state.parameters() if p.requires_grad]
        self.disc_optimizer = torch.optim.Adam(
            disc_params, lr=cfg.disc_lr, weight_decay=cfg.disc_weight_decay
        )
        proxy_params = [] if self.proxy is None else [
            p for p in self.proxy.parameters() if p.requires_grad  # the RND target is frozen
        ]
        self.proxy_optimizer = (
            torch.optim.Adam(proxy_params, lr=cfg.rnd_lr) if proxy_params else None
        )
        self.rng = np.random.default_rng(seed)
        """The ranking's stream (partition ties, random modes, archive samples)."""
        self.shuffle_rng = np.random.default_rng(None if seed is None else seed + 2)
        """The minibatches' stream (kept apart: training never shifts the ranking's draws)."""

    # ------------------------------------------------------------------------- one call
    def step(
        self,
        batch: AsorBatch,
        minibatch_size: int | None = None,
        rows: float | None = None,
        share: tuple[int, int] = (0, 1),
    ) -> AsorResult:
        """`rank(batch)` then `learn(...)` on what it returned: Δr with ω from before this
        call, then the networks' steps. See `learn` for the arguments."""
        result = self.rank(batch)
        self.learn(result, batch, minibatch_size, rows, share)
        return result

    def rank(self, batch: AsorBatch) -> AsorResult:
        """Steps 1-7 on `batch` (`asor_update`): D_P, Δr and λ, the networks not yet trained
        (a caller that needs ω of other rows before training, e.g. MAPLE's model rows, reads
        it between `rank` and `learn`)."""
        return asor_update(self.cfg, self.state, self.proxy, batch, self.rng)

    def learn(
        self,
        result: AsorResult,
        batch: AsorBatch,
        minibatch_size: int | None = None,
        rows: float | None = None,
        share: tuple[int, int] = (0, 1),
    ) -> None:
        """Train the discriminator on `result`'s D_P vs D_Q and the proxy on the ranked states;
        their metrics join `result.metrics` (means over the minibatches).

        `minibatch_size`: rows per optimiser step (None: the whole aux batch at once).
        `rows`: rows to train on per network (None: `aux_epochs` passes over its batch, one
        when unset). `share`: (rank, world size) when several Learners call this with the
        same whole batch (module docstring)."""
        rank, size = share
        proxy_in = result.proxy_inputs or ranked_proxy_inputs(batch)
        disc_feats, labels = result.disc_features, result.disc_labels
        if size > 1:
            disc_feats, labels = even_share(disc_feats, rank, size), even_share(labels, rank, size)
            proxy_in = ProxyInputs(
                *(even_share(getattr(proxy_in, f.name), rank, size)
                  for f in dataclasses.fields(ProxyInputs))
            )  # fmt: skip
        with torch.enable_grad():  # callers may run under no_grad (RLlib's connectors do)
            metrics = self.train_discriminator(disc_feats, labels, minibatch_size, rows, size > 1)
            if self.proxy is not None and self.proxy_optimizer is not None:
                metrics.update(self.train_proxy(proxy_in, minibatch_size, rows, size > 1))
        if result.metrics:
            result.metrics.update(metrics)

    def train_discriminator(
        self,
        features: torch.Tensor,
        labels: torch.Tensor,
        minibatch_size: int | None,
        rows: float | None,
        average: bool = False,
    ) -> dict[str, float]:
        """The discriminator's steps on D_P (label 1) vs D_Q (0): the class-balanced GAN loss
        plus the gradient penalty and logit regularisation; the means of their statistics."""
        cfg, disc = self.cfg, self.state.disc
        sums: dict[str, float] = {}
        steps = 0
        for idx in self._minibatches(features.shape[0], minibatch_size, rows):
            loss, stats = disc.training_loss(
                features[idx], labels[idx], cfg.label_smoothing,
                cfg.disc_grad_penalty, cfg.disc_logit_reg,
            )  # fmt: skip
            self._optimise(self.disc_optimizer, loss, average)
            for k, v in stats.items():
                sums[k] = sums.get(k, 0.0) + float(v)
            steps += 1
        return {k: v / steps for k, v in sums.items()} if steps else {}

    def train_proxy(
        self,
        inputs: ProxyInputs,
        minibatch_size: int | None,
        rows: float | None,
        average: bool = False,
    ) -> dict[str, float]:
        """The proxy's steps on the batch's states (RND's prediction error, or the ensemble's
        dynamics loss); the mean loss as `rnd_loss` / `ensemble_loss`."""
        assert self.proxy is not None and self.proxy_optimizer is not None
        total, steps = 0.0, 0
        for idx in self._minibatches(inputs.features.shape[0], minibatch_size, rows):
            part = ProxyInputs(
                *(None if (v := getattr(inputs, f.name)) is None else v[idx]
                  for f in dataclasses.fields(ProxyInputs))
            )  # fmt: skip
            loss = self.proxy.loss(part)
            self._optimise(self.proxy_optimizer, loss, average)
            total += float(loss.detach())
            steps += 1
        name = "ensemble_loss" if self.cfg.proxy == "ensemble" else "rnd_loss"
        return {name: total / steps} if steps else {}

    def _optimise(self, optimizer: torch.optim.Optimizer, loss: torch.Tensor, average: bool) -> None:
        optimizer.zero_grad(set_to_none=True)
        loss.backward()
        if average:  # every rank takes the same number of steps (equal shares)
            world = dist.get_world_size()
            for group in optimizer.param_groups:
                for p in group["params"]:
                    if p.grad is None:
                        p.grad = torch.zeros_like(p)
                    dist.all_reduce(p.grad)
                    p.grad /= world
        optimizer.step()

    def _minibatches(
        self, n: int, minibatch_size: int | None, rows: float | None
    ) -> Iterator[torch.Tensor]:
        """Row indices of each step: `rows` rows (default `aux_epochs` passes over n) in
        minibatches of `minibatch_size`, each pass a fresh permutation (as RLlib's cyclic
        minibatch iterator: the last minibatch of a pass is filled from the next pass)."""
        if n == 0:
            return
        passes = 1.0 if self.cfg.aux_epochs is None else float(self.cfg.aux_epochs)
        budget = passes * n if rows is None else float(rows)
        size = n if not minibatch_size else min(int(minibatch_size), n)
        device = self.state.auto_lambda.device
        order = torch.from_numpy(self.shuffle_rng.permutation(n)).to(device)
        pos, done = 0, 0
        while done < budget:
            idx = order[pos : pos + size]
            pos += size
            while idx.shape[0] < size:  # the pass ended: fill from the next one
                order = torch.from_numpy(self.shuffle_rng.permutation(n)).to(device)
                pos = size - idx.shape[0]
                idx = torch.cat([idx, order[:pos]])
            yield idx
            done += size

    # ---------------------------------------------------------------------- checkpoints
    def get_state(self) -> dict[str, Any]:
        """Everything the trainer keeps, as CPU tensors and plain values."""
        return {
            "format": STATE_FORMAT,
            "modules": _to_cpu(self.state_dict()),
            "disc_optimizer": _to_cpu(self.disc_optimizer.state_dict()),
            "proxy_optimizer": (
                None if self.proxy_optimizer is None else _to_cpu(self.proxy_optimizer.state_dict())
            ),
            "rng": self.rng.bit_generator.state,
            "shuffle_rng": self.shuffle_rng.bit_generator.state,
        }

    def set_state(self, state: dict[str, Any]) -> None:
        """Restore `get_state()`'s output onto this trainer's device; ValueError (one line) for
        a state of another layout, e.g. from a checkpoint of an older rllib-asor."""
        if not isinstance(state, dict) or state.get("format") != STATE_FORMAT:
            raise ValueError(
                "this ASOR state was written by an older rllib-asor (ASOR's discriminator and "
                "proxy were separate RLlib modules then) and cannot be restored by this "
                "version; allowed: a checkpoint written by this version, or train again"
            )
        device = self.state.auto_lambda.device
        self.load_state_dict({k: torch.as_tensor(v).to(device) for k, v in state["modules"].items()})
        self.disc_optimizer.load_state_dict(_to_tensors(state["disc_optimizer"]))
        if self.proxy_optimizer is not None and state.get("proxy_optimizer") is not None:
            self.proxy_optimizer.load_state_dict(_to_tensors(state["proxy_optimizer"]))
        self.rng.bit_generator.state = state["rng"]
        self.shuffle_rng.bit_generator.state = state["shuffle_rng"]


def even_share(rows: torch.Tensor | None, rank: int, size: int) -> torch.Tensor | None:
    """This rank's block of `rows`: ⌊N / size⌋ rows each (the remainder is left out)."""
    if rows is None:
        return None
    k = rows.shape[0] // size
    return rows[rank * k : (rank + 1) * k]


def _to_cpu(x: Any) -> Any:
    """A copy of `x` with every tensor on the CPU (never aliasing the live tensors: an
    optimiser loading the state keeps what it is given)."""
    if isinstance(x, torch.Tensor):
        return x.detach().to("cpu", copy=True)
    if isinstance(x, dict):  # state_dict()'s OrderedDict too
        return {k: _to_cpu(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return type(x)(_to_cpu(v) for v in x)
    return x


def _to_tensors(x: Any) -> Any:
    """`x` with numpy arrays as tensors (a state that went through RLlib's numpy conversion)."""
    if isinstance(x, np.ndarray):
        return torch.from_numpy(x.copy())
    if isinstance(x, dict):
        return {k: _to_tensors(v) for k, v in x.items()}
    if isinstance(x, list | tuple):
        return type(x)(_to_tensors(v) for v in x)
    return x


class _seeded:
    """Initialise under `seed` without touching the process's global torch RNG stream."""

    def __init__(self, seed: int | None) -> None:
        self.seed = seed
        self._fork: Any = None

    def __enter__(self) -> None:
        if self.seed is not None:
            self._fork = torch.random.fork_rng()
            self._fork.__enter__()
            torch.manual_seed(self.seed)

    def __exit__(self, *exc: Any) -> None:
        if self._fork is not None:
            self._fork.__exit__(*exc)
