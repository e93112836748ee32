"""MOPO's probabilistic dynamics ensemble, all members in one batched network.

Faithful to the PyTorch port MAPLE+SRPO runs on (`AIDefender/SRPO`, a fork of
`polixir/OfflineRL`): `offlinerl/utils/net/model/ensemble.py` (`EnsembleLinear`,
`EnsembleTransition`, mode 'normalize') and `offlinerl/algo/modelbase/maple_st.py`
(`train_transition`, `_train_transition`, `_eval_transition`, `_select_best_indexes`):

- K members of 4 swish layers; every layer is one `[K, in, out]` weight applied with a batched
  matmul (`torch.baddbmm`), so all members run in one call, no Python loop over members;
- inputs: observation normalised by the data's mean/std, raw action; outputs: a Gaussian over
  (next observation, reward); the observation mean is a residual (s + Δ), the reward is direct;
- log-std soft-clamped between learned bounds (init −5 and 1), penalised by
  0.01·Σ(max_logstd − min_logstd)·2 as MOPO;
- loss: −Σ log N(target | μ, σ) over members, rows and dims (the port's sum, not a mean);
- training: a holdout of min(20 % + 1, 1000) rows; every epoch each member draws its own
  bootstrap of the training rows; after each epoch the per-member validation MSE; a member's
  best weights are kept; stop after 5 epochs in which no member improved; the `num_elites`
  members with the lowest validation MSE are the elites (rollouts and the penalty use those).

`looped_forward` runs the same weights one member at a time (the speed benchmark's baseline and
the test of the batched forward).
"""

from __future__ import annotations

import hashlib
import json
import math
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from torch import nn

from rllib_asor.devices import module_device


def soft_clamp(x: torch.Tensor, lo: torch.Tensor, hi: torch.Tensor) -> torch.Tensor:
    """Clamp keeping the gradient (`offlinerl/utils/function.py soft_clamp`)."""
    x = hi - F.softplus(hi - x)
    return lo + F.softplus(x - lo)


class EnsembleLinear(nn.Module):
    """K linear layers as one `[K, in, out]` weight; input `[K, N, in]` → `[K, N, out]`."""

    def __init__(self, in_features: int, out_features: int, members: int) -> None:
        super().__init__()
        self.weight = nn.Parameter(torch.zeros(members, in_features, out_features))
        self.bias = nn.Parameter(torch.zeros(members, 1, out_features))
        nn.init.trunc_normal_(self.weight, std=1 / (2 * in_features**0.5))

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return torch.baddbmm(self.bias, x, self.weight)


class GaussianEnsemble(nn.Module):
    """K Gaussian dynamics models p_k(s′, r | s, a) in one batched network (module doc)."""

    def __init__(
        self,
        obs_dim: int,
        action_dim: int,
        members: int = 7,
        elites: int = 5,
        hidden: int = 200,
        layers: int = 4,
    ) -> None:
        super().__init__()
        if not 1 <= elites <= members:
            raise ValueError(
                f"elites={elites} is invalid: allowed 1 <= elites <= members={members}"
            )
        self.obs_dim, self.action_dim, self.members = obs_dim, action_dim, members
        self.num_elites = elites
        dims = [obs_dim + action_dim] + [hidden] * layers
        self.hidden_layers = nn.ModuleList(
            EnsembleLinear(i, o, members) for i, o in zip(dims[:-1], dims[1:], strict=True)
        )
        self.out = EnsembleLinear(hidden, 2 * (obs_dim + 1), members)
        self.max_logstd = nn.Parameter(torch.ones(obs_dim + 1))
        self.min_logstd = nn.Parameter(torch.full((obs_dim + 1,), -5.0))
        self.register_buffer("obs_mean", torch.zeros(obs_dim))
        self.register_buffer("obs_std", torch.ones(obs_dim))
        self.register_buffer("elite_idx", torch.arange(elites))

    def set_normalizer(self, obs: torch.Tensor) -> None:
        """Input statistics from the data's observations (the port: obs and next obs)."""
        self.obs_mean.copy_(obs.mean(0))
        self.obs_std.copy_(obs.std(0))

    def _inputs(self, obs: torch.Tensor, actions: torch.Tensor) -> torch.Tensor:
        x = torch.cat([(obs - self.obs_mean) / (self.obs_std + 1e-8), actions], dim=-1)
        return x if x.dim() == 3 else x.unsqueeze(0).expand(self.members, -1, -1)

    def _head(self, out: torch.Tensor, obs: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        mu, logstd = out.chunk(2, dim=-1)
        logstd = soft_clamp(logstd, self.min_logstd, self.max_logstd)
        mu = torch.cat([mu[..., :-1] + obs, mu[..., -1:]], dim=-1)  # residual on s only
        return mu, logstd

    def forward(
        self, obs: torch.Tensor, actions: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """(μ, log σ) of (s′, r), each `[K, N, obs_dim + 1]`; obs/actions `[N, ·]` (every member
        sees the same rows) or `[K, N, ·]` (each member its own rows)."""
        h = self._inputs(obs, actions)
        for layer in self.hidden_layers:
            h = F.silu(layer(h))  # swish
        return self._head(self.out(h), obs)

    def elites(self, obs: torch.Tensor, actions: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """`forward` of the elite members only (the others are not computed): `[E, N, obs_dim + 1]`
        each; obs/actions `[N, ·]`."""
        idx = self.elite_idx
        x = torch.cat([(obs - self.obs_mean) / (self.obs_std + 1e-8), actions], dim=-1)
        h = x.unsqueeze(0).expand(len(idx), -1, -1)
        for layer in self.hidden_layers:
            h = F.silu(torch.baddbmm(layer.bias[idx], h, layer.weight[idx]))
        return self._head(torch.baddbmm(self.out.bias[idx], h, self.out.weight[idx]), obs)


def looped_forward(
    model: GaussianEnsemble, obs: torch.Tensor, actions: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """The same networks one member at a time (`x @ W_k + b_k` per member, a Python loop): the
    baseline the batched forward is measured against (benchmarks/maple_speed.py)."""
    x = model._inputs(obs, actions)
    mus, logstds = [], []
    for k in range(model.members):
        h = x[k]
        for layer in model.hidden_layers:
            h = F.silu(torch.addmm(layer.bias[k], h, layer.weight[k]))
        o = torch.addmm(model.out.bias[k], h, model.out.weight[k]).unsqueeze(0)
        mu, logstd = model._head(o, obs[k] if obs.dim() == 3 else obs)
        mus.append(mu[0])
        logstds.append(logstd[0])
    return torch.stack(mus), torch.stack(logstds)


def gaussian_nll(
    mu: torch.Tensor, logstd: torch.Tensor, target: torch.Tensor, model: GaussianEnsemble
) -> torch.Tensor:
    """The port's training loss (`_train_transition`): −Σ log N(target | μ, e^{log σ}) over members,
    rows and dims, plus 0.01·Σ 2·max_logstd − 0.01·Σ 2·min_logstd."""
    nll = -torch.distributions.Normal(mu, logstd.exp()).log_prob(target).sum()
    return nll + 0.01 * (2.0 * model.max_logstd).sum() - 0.01 * (2.0 * model.min_logstd).sum()


def validation_mse(
    model: GaussianEnsemble, obs: torch.Tensor, actions: torch.Tensor, target: torch.Tensor
) -> torch.Tensor:
    """Per-member mean squared error of μ on held-out rows, `[K]` (`_eval_transition`,
    `inc_var_loss=False`: what early stopping and the elite choice use)."""
    with torch.no_grad():
        mu, _ = model(obs, actions)
        return (mu - target).pow(2).mean(dim=(1, 2))


def choose_elites(val_losses: Sequence[float], n: int) -> list[int]:
    """Indices of the `n` members with the lowest validation loss, best first
    (`_select_best_indexes`)."""
    order = sorted(range(len(val_losses)), key=lambda i: (val_losses[i], i))
    return order[:n]


@dataclass
class EnsembleReport:
    """What `train_ensemble` did."""

    epochs: int
    val_losses: list[float]
    elites: list[int]
    seconds: float
    train_rows: int
    holdout_rows: int
    stopped_early: bool
    history: list[list[float]] = field(default_factory=list)


def train_ensemble(
    model: GaussianEnsemble,
    obs: np.ndarray,
    actions: np.ndarray,
    next_obs: np.ndarray,
    rewards: np.ndarray,
    *,
    seed: int = 0,
    batch_size: int = 256,
    lr: float = 1e-3,
    weight_decay: float = 7.5e-5,
    patience: int = 5,
    max_epochs: int | None = None,
    holdout_max: int = 1000,
    log: Callable[[str], None] | None = None,
) -> EnsembleReport:
    """Train `model` as the port's `train_transition` (module doc); returns its report.

    AdamW(lr 1e-3, weight decay 7.5e-5) as `maple_st.py`'s `algo_init`. `max_epochs` caps the
    loop (None: until `patience` epochs without improvement, as the port)."""
    t0 = time.perf_counter()
    gen = torch.Generator().manual_seed(seed)  # on the CPU: the same split on every device
    rng = np.random.default_rng(seed)
    device = module_device(model)

    def on_device(x: np.ndarray, dtype: torch.dtype | None = torch.float32) -> torch.Tensor:
        return torch.as_tensor(x, dtype=dtype, device=device)

    x_obs, x_act = on_device(obs), on_device(actions)
    target = torch.cat([on_device(next_obs), on_device(rewards).reshape(-1, 1)], dim=-1)
    n = x_obs.shape[0]
    val_size = min(int(n * 0.2) + 1, holdout_max)
    if n - val_size < 1:
        raise ValueError(f"train_ensemble: {n} rows are too few (need at least 2)")
    perm = torch.randperm(n, generator=gen, device=gen.device).to(device)
    tr, va = perm[val_size:], perm[:val_size]
    model.set_normalizer(torch.cat([x_obs, on_device(next_obs)]))
    opt = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=weight_decay)
    best = [math.inf] * model.members
    saved = {k: v.detach().clone() for k, v in model.state_dict().items()}
    epoch, stale, history = 0, 0, []
    k = model.members
    while max_epochs is None or epoch < max_epochs:
        epoch += 1
        idx = tr[on_device(rng.integers(0, len(tr), size=(k, len(tr))), None)]
        for start in range(0, idx.shape[1], batch_size):
            b = idx[:, start : start + batch_size]
            mu, logstd = model(x_obs[b], x_act[b])
            loss = gaussian_nll(mu, logstd, target[b], model)
            opt.zero_grad()
            loss.backward()
            opt.step()
        new = validation_mse(model, x_obs[va], x_act[va], target[va]).tolist()
        history.append(new)
        improved = [i for i in range(k) if new[i] < best[i]]
        for i in improved:
            best[i] = new[i]
        if improved:
            _save_members(model, saved, improved)
            stale = 0
        else:
            stale += 1
        if log is not None:
            log(f"ensemble epoch {epoch}: holdout MSE {np.round(new, 5).tolist()}")
        if stale >= patience:
            break
    # Restore each member's best weights (`set_select` copies the saved weights back).
    _load_members(model, saved, list(range(k)))
    elites = choose_elites(best, model.num_elites)
    model.elite_idx.copy_(torch.as_tensor(elites, device=model.elite_idx.device))
    return EnsembleReport(
        epochs=epoch,
        val_losses=[float(v) for v in best],
        elites=elites,
        seconds=time.perf_counter() - t0,
        train_rows=len(tr),
        holdout_rows=val_size,
        stopped_early=stale >= patience,
        history=history,
    )


def _member_params(model: GaussianEnsemble) -> list[str]:
    return [n for n, _ in model.named_parameters() if n.endswith(("weight", "bias"))]


def _save_members(model: GaussianEnsemble, saved: dict[str, torch.Tensor], idx: list[int]) -> None:
    state = model.state_dict()
    for name in _member_params(model):
        saved[name][idx] = state[name][idx].detach().clone()


def _load_members(model: GaussianEnsemble, saved: dict[str, torch.Tensor], idx: list[int]) -> None:
    with torch.no_grad():
        params = dict(model.named_parameters())
        for name in _member_params(model):
            params[name][idx] = saved[name][idx]


# ------------------------------------------------------------------------------ the cache
def dataset_key(paths: Sequence[str], settings: dict[str, Any], extra: str = "") -> str:
    """A short key for (dataset parts, ensemble settings): paired runs share the ensemble.

    The data is identified by the bytes of the parts' parquet files, not by their paths or
    modification times: a copied, moved or freshly cloned dataset finds its ensemble, and
    rewritten rows never do.
    """
    parts = []
    for p in paths:
        h = hashlib.sha256()
        for f in sorted(Path(p).glob("*.parquet")):
            h.update(f.read_bytes())
        parts.append(h.hexdigest())
    blob = json.dumps(
        {"parts": sorted(parts), "settings": settings, "extra": extra}, sort_keys=True
    )
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def cache_path(cache_dir: str | os.PathLike[str], key: str, seed: int) -> Path:
    """Where the ensemble of (dataset key, seed) is saved."""
    return Path(cache_dir) / f"ensemble-{key}-seed{seed}.pt"


def save_ensemble(model: GaussianEnsemble, report: EnsembleReport, path: Path) -> None:
    """Atomic save (temp file + rename), so that parallel runs never read half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    shape = {
        "obs_dim": model.obs_dim,
        "action_dim": model.action_dim,
        "members": model.members,
        "elites": model.num_elites,
        "hidden": model.out.weight.shape[1],
        "layers": len(model.hidden_layers),
    }
    blob = {"shape": shape, "state": model.state_dict(), "report": asdict(report)}
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    os.close(fd)
    try:
        torch.save(blob, tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def load_ensemble(path: Path) -> tuple[GaussianEnsemble, dict[str, Any]]:
    """The ensemble saved at `path` and its training report."""
    blob = torch.load(path, map_location="cpu", weights_only=False)
    model = GaussianEnsemble(**blob["shape"])
    model.load_state_dict(blob["state"])
    return model, blob["report"]
