"""One ASOR update on one policy's train batch, in the order of the paper's Algorithm 1.

Plain torch, no RLlib: the PPO connector piece, the SAC and CQL glue all build an
`AsorBatch` and call `asor_update`, then let their Learner train the discriminator and the
proxy on the batches it returns (the rewards use ω from *before* that training step).

    1. V(s): given, from the algorithm's own critic (no gradient)
    2. c(s): the visitation proxy folds the batch in and counts it
    3. D_P:  partition by value, then by count; from the current batch (paper) or from the
             archive of the best episodes per dynamics (robust default)
    4. ω(s): the discriminator's logits on the batch, before its own update
    5. b(s): the bonus form, normalised by its running statistics, optionally shaped
    6. λ:    schedule / auto (PI-Lagrangian), × the env reward's running scale, 0 during the
             warm-up, capped so that |λ·b| stays ≤ bonus_share_max × that scale
    7. r ← r + λ·(γ·b(s′) − b(s))  (potential form, default)  or  r + λ·b(s)  (paper)
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Hashable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import torch
from torch import nn

from rllib_asor.asor.archive import StateArchive
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import Discriminator, discriminator_loss
from rllib_asor.asor.networks import RunningMeanStd
from rllib_asor.asor.partition import partition
from rllib_asor.asor.proxy import ProxyInputs, VisitationProxy
from rllib_asor.asor.reward import (
    dual_ascent_step,
    explained_variance,
    potential_shaping,
    reward_bonus,
    reward_scale,
    scheduled_lambda,
    standardize,
)

logger = logging.getLogger(__name__)


class AsorState(nn.Module):
    """Everything ASOR keeps between updates, as one module (all of it checkpointed):
    the discriminator, the running normalisers of the bonus and of the env reward, the
    archive (real_source="archive"), λ of `lambda_="auto"` and the warm-up latch."""

    def __init__(self, cfg: AsorConfig, feature_dim: int) -> None:
        super().__init__()
        self.disc = Discriminator(feature_dim, cfg.disc_hiddens, cfg.disc_input_norm)
        self.bonus_rms = RunningMeanStd(1)
        self.reward_rms = RunningMeanStd(1)
        self.archive = (
            StateArchive(feature_dim, cfg.archive_size, cfg.dynamics_buckets)
            if cfg.real_source == "archive"
            else None
        )
        init = cfg.lambda_init if cfg.lambda_ == "auto" else 0.0
        self.register_buffer("auto_lambda", torch.tensor(float(init)))
        self.register_buffer("critic_ready", torch.tensor(0.0 if cfg.lambda_warmup else 1.0))


@dataclass
class Chunk:
    """One episode chunk of the batch: rows [start, stop) of the valid steps."""

    key: Hashable
    start: int
    stop: int
    dynamics_id: int = 0


@dataclass
class AsorBatch:
    """One policy's valid steps (N rows) and what the optional steps need."""

    features: torch.Tensor
    """[N, D] flat features of s (the key-selected observation)."""
    env_rewards: torch.Tensor
    """[N] the env's rewards."""
    values: torch.Tensor
    """[N] V(s) from the critic."""
    gamma: float
    timestep: float = 0.0
    """Env steps sampled so far (λ schedules)."""
    proxy_inputs: ProxyInputs | None = None
    """Inputs of the proxy (None: `features` alone)."""
    next_features: torch.Tensor | None = None
    """[N, D] features of s′ (potential shaping)."""
    terminateds: torch.Tensor | None = None
    """[N] whether s′ is terminal."""
    next_values: torch.Tensor | None = None
    """[N] V(s′) (the critic's explained variance for the warm-up; on-policy only)."""
    chunks: Sequence[Chunk] | None = None
    """Episode chunks in row order (the archive and the warm-up; on-policy only)."""
    ranked: torch.Tensor | None = None
    """Indices of the rows that are ranked (proxy counts, D_P, the discriminator's D_Q) when
    not all are; `values` and `proxy_inputs` then hold those rows only. Every row gets the
    bonus. Set where the discriminator trains on fewer rows than the batch holds (SAC's fast
    path: one minibatch of a call's 16), so V(s) and the counts of the others are not needed."""


def ranked_proxy_inputs(batch: AsorBatch) -> ProxyInputs:
    """What the proxy observes, counts and trains on: the ranked rows' inputs."""
    if batch.proxy_inputs is not None:
        return batch.proxy_inputs
    return ProxyInputs(batch.features if batch.ranked is None else batch.features[batch.ranked])


def concat_batches(batches: Sequence[AsorBatch]) -> AsorBatch:
    """One `AsorBatch` of the rows of `batches` in order (chunks shifted to their rows).

    Several Learners each hold a shard of the train batch; run on the concatenation, the same
    update gives every Learner the same state (docs/algorithm.md, "Many Learners"). Optional
    fields are kept only when every batch has them; `gamma` and `timestep` come from the first.
    """
    if not batches:
        raise ValueError("concat_batches needs at least one AsorBatch")
    first = batches[0]

    def cat(get: Callable[[Any], Any]) -> Any:
        parts = [get(b) for b in batches]
        return None if any(p is None for p in parts) else torch.cat(parts)

    chunks: list[Chunk] | None = []
    ranked: list[torch.Tensor] | None = [] if any(b.ranked is not None for b in batches) else None
    offset = 0
    for b in batches:
        if ranked is not None:
            rows = b.ranked
            if rows is None:
                rows = torch.arange(b.features.shape[0], device=b.features.device)
            ranked.append(rows.to(b.features.device) + offset)
        if b.chunks is None or chunks is None:
            chunks = None
        else:
            chunks += [
                Chunk(c.key, c.start + offset, c.stop + offset, c.dynamics_id) for c in b.chunks
            ]
        offset += b.features.shape[0]
    proxy = None
    if all(b.proxy_inputs is not None for b in batches):
        proxy = ProxyInputs(
            cat(lambda b: b.proxy_inputs.features),
            cat(lambda b: b.proxy_inputs.actions),
            cat(lambda b: b.proxy_inputs.next_features),
            cat(lambda b: b.proxy_inputs.dynamics_ids),
        )
    return AsorBatch(
        features=cat(lambda b: b.features),
        env_rewards=cat(lambda b: b.env_rewards),
        values=cat(lambda b: b.values),
        gamma=first.gamma,
        timestep=first.timestep,
        proxy_inputs=proxy,
        next_features=cat(lambda b: b.next_features),
        terminateds=cat(lambda b: b.terminateds),
        next_values=cat(lambda b: b.next_values),
        chunks=chunks,
        ranked=None if ranked is None else torch.cat(ranked),
    )


@dataclass
class AsorResult:
    """What the caller applies and trains."""

    reward_delta: torch.Tensor
    """[N] λ·(γ·b(s′) − b(s)) (potential) or λ·b(s) (direct), to add to the env rewards."""
    disc_features: torch.Tensor
    """[M, D] the discriminator's train batch: D_P then D_Q."""
    disc_labels: torch.Tensor
    """[M] 1 for D_P, 0 for D_Q."""
    metrics: dict[str, float] = field(default_factory=dict)
    lam: float = 0.0
    """λ as applied: scaled, 0 when inactive, capped (what multiplies the bonus)."""
    proxy_inputs: ProxyInputs | None = None
    """What the proxy observed and counted (its train batch); None without a proxy."""


@torch.no_grad()
def asor_update(
    cfg: AsorConfig,
    state: AsorState,
    proxy: VisitationProxy | None,
    batch: AsorBatch,
    rng: np.random.Generator,
) -> AsorResult:
    """Steps 1-7 of the module docstring for one policy's batch."""
    feats, n = batch.features, batch.features.shape[0]
    # The ranked rows (all, unless `batch.ranked` names fewer): they form D_Q.
    rank_feats = feats if batch.ranked is None else feats[batch.ranked]
    r = rank_feats.shape[0]
    # 1. V(s): `batch.values`, from the algorithm's critic.
    # 2. The visitation proxy observes the batch, then counts it.
    counts, proxy_in = None, None
    if proxy is not None:
        proxy_in = ranked_proxy_inputs(batch)
        proxy.observe(proxy_in)
        counts = proxy.count(proxy_in)
    # 3. The real set D_P, and the discriminator's train batch.
    rho_value, rho_count = cfg.effective_rhos
    from_archive = state.archive is not None and batch.chunks is not None
    if from_archive:
        _archive_episodes(state.archive, batch)
        cand, cand_rtg = state.archive.sample(r, _torch_generator(rng))
        cand_counts = None
        if proxy is not None and cfg.proxy != "ensemble" and len(cand):
            cand_counts = proxy.count(ProxyInputs(cand))
        mode = cfg.mode if cand_counts is not None or cfg.mode in ("srpo", "random") else "srpo"
        real = (
            partition(cand_rtg, cand_counts, rho_value, rho_count, mode=mode, rng=rng)
            if len(cand)
            else torch.zeros(0, dtype=torch.bool, device=cand.device)
        )
        # Shuffled: the Learner cuts this batch into minibatches in row order.
        k, device = int(real.sum()), feats.device
        order = torch.from_numpy(rng.permutation(k + r)).to(device)
        disc_feats = torch.cat([cand[real].to(feats), rank_feats])[order]
        labels = torch.cat(
            [torch.ones(k, dtype=feats.dtype, device=device),
             torch.zeros(r, dtype=feats.dtype, device=device)]
        )[order]
        batch_real = torch.zeros(r, dtype=torch.bool, device=device)
    else:
        # The paper (and off-policy/offline, whose replay batch already spans every
        # dynamics seen): D_P is the top of the current batch.
        batch_real = partition(batch.values, counts, rho_value, rho_count, mode=cfg.mode, rng=rng)
        disc_feats, labels = rank_feats, batch_real.float()
    has_real = bool((labels > 0.5).any())
    potential = cfg.shaping == "potential"
    if potential and (batch.next_features is None or batch.terminateds is None):
        _warn_once(
            "asor.shaping='potential': this batch has no next states (a recurrent "
            "module's padded batch?); using the direct form r + λ·b(s)"
        )
        potential = False
    # 4. ω on the batch, before this update's discriminator step: one pass over s, s′ (the
    #    potential) and, for λ="auto", the archive's real states (the JS estimate on D_P ∪ D_Q).
    state.disc.observe(disc_feats)
    auto = cfg.lambda_ == "auto"
    extra = disc_feats[labels > 0.5] if auto and from_archive else None
    parts = [feats]
    parts += [batch.next_features] if potential else []
    parts += [extra] if extra is not None else []
    out = state.disc(torch.cat(parts)) if len(parts) > 1 else state.disc(feats)
    logits = out[:n]
    rank_logits = logits if batch.ranked is None else logits[batch.ranked]

    # 5. The bonus b(s) (with potential shaping, b is the potential Φ).
    raw = _raw_bonus(cfg, logits)
    normalise = _bonus_normaliser(cfg, state, raw, update_running=True)
    bonus = potential_of = normalise(raw)
    if potential:
        next_bonus = normalise(_raw_bonus(cfg, out[n : 2 * n]))
        bonus = potential_shaping(bonus, next_bonus, batch.terminateds, batch.gamma)
    # 6. λ for this batch ("auto": from the discriminator's JS estimate on its own batch).
    js = float("nan")
    if auto:
        if extra is None:  # D_P is the batch's top: its own rows and labels
            js_logits, js_labels = rank_logits, labels
        else:  # D_P from the archive, D_Q the batch
            js_logits = torch.cat([out[out.shape[0] - extra.shape[0] :], rank_logits])
            js_labels = torch.cat([labels.new_ones(extra.shape[0]), labels.new_zeros(r)])
        _, disc_stats = discriminator_loss(js_logits, js_labels)
        js = disc_stats["js_estimate"].item()
    lam = _lambda(cfg, state, js, batch.timestep)
    state.reward_rms.update(batch.env_rewards.reshape(-1, 1).float())
    scale = reward_scale(state.reward_rms) if cfg.lambda_relative else 1.0
    ev = _critic_ev(batch)
    if ev is None or ev > 0.0:  # no episode structure (off-policy): nothing to wait for
        state.critic_ready.fill_(1.0)
    active = bool(state.critic_ready.item()) and has_real
    lam_eff = lam * scale if active else 0.0
    rms = max(reward_scale(state.reward_rms), 1e-8)
    share = lam_eff * float(potential_of.abs().mean()) / rms if n else 0.0
    capped = 0.0 < cfg.bonus_share_max < share
    if capped:  # the cap on the bonus's share of the reward
        lam_eff *= cfg.bonus_share_max / share
    # 7. The amount added to the rewards.
    delta = (lam_eff * bonus).to(batch.env_rewards.dtype)
    if not torch.isfinite(delta).all():
        raise ValueError("ASOR: the reward bonus is NaN/inf")
    metrics = _metrics(state, lam_eff, scale, bonus, delta, rank_logits, batch, batch_real, labels)
    if metrics:
        metrics.update(
            {
                # "The bonus": the per-step amount added to the reward, mean |Δr| ÷ the env
                # reward's running RMS; the potential's size |λ·Φ| (what bonus_share_max caps;
                # the same number without potential shaping) is `potential_share`.
                "bonus_share": float(delta.abs().mean() / rms),
                "potential_share": float((lam_eff * potential_of).abs().mean() / rms),
                "active": float(active),
                "share_capped": float(capped),
                "potential": float(potential),
            }
        )
        if ev is not None:  # no episode chunks (off-policy, offline): absent, never NaN
            metrics["critic_ev"] = ev
    return AsorResult(delta, disc_feats, labels, metrics, lam_eff, proxy_in)


@torch.no_grad()
def bonus_for_rows(
    cfg: AsorConfig,
    state: AsorState,
    lam: float,
    features: torch.Tensor,
    next_features: torch.Tensor,
    terminateds: torch.Tensor,
    gamma: float,
) -> torch.Tensor:
    """λ·b(s) (or λ·(γ·b(s′) − b(s))) for rows that were not ranked, e.g. MAPLE's model rows,
    after `asor_update` on the ranked ones: the same bonus form, normalisation and shaping,
    with the discriminator and running statistics as that update left them (not updated
    again; `bonus_norm="batch"` takes these rows' own statistics). `lam` is `AsorResult.lam`."""
    raw = _raw_bonus(cfg, state.disc(features))
    normalise = _bonus_normaliser(cfg, state, raw, update_running=False)
    bonus = normalise(raw)
    if cfg.shaping == "potential":
        next_bonus = normalise(_raw_bonus(cfg, state.disc(next_features)))
        bonus = potential_shaping(bonus, next_bonus, terminateds, gamma)
    return lam * bonus


def _raw_bonus(cfg: AsorConfig, logits: torch.Tensor) -> torch.Tensor:
    """The bonus form of the discriminator's logits, before normalising."""
    return reward_bonus(logits, cfg.reward_form, cfg.log_omega_min, cfg.logit_clip)


def _bonus_normaliser(
    cfg: AsorConfig, state: AsorState, raw: torch.Tensor, *, update_running: bool
) -> Callable[[torch.Tensor], torch.Tensor]:
    """The map raw bonus → the bonus used, fixed for this batch (s and s′ alike); the only
    place the bonus is normalised. `update_running`: fold `raw` into the running statistics
    first (`bonus_norm="running"`)."""
    if cfg.bonus_norm == "off":
        return lambda b: b
    if cfg.bonus_norm == "running":
        if update_running:
            state.bonus_rms.update(raw.reshape(-1, 1))
        mean, var = state.bonus_rms.mean.reshape(()), state.bonus_rms.var.reshape(())
    else:  # "batch"
        mean, var = raw.mean(), raw.var(unbiased=False)
    return lambda b: standardize(b, mean, var, cfg.bonus_clip)


def _lambda(cfg: AsorConfig, state: AsorState, js_estimate: float, timestep: float) -> float:
    """λ before scaling; with "auto", the PI-Lagrangian on this batch's JS estimate: the
    integral (dual-ascent) term from earlier batches plus Kp × this batch's violation."""
    if cfg.lambda_ != "auto":
        return scheduled_lambda(cfg.lambda_, timestep)
    integral = float(state.auto_lambda.item())
    state.auto_lambda.fill_(
        dual_ascent_step(integral, js_estimate, cfg.lambda_target, cfg.lambda_lr, cfg.lambda_max)
    )
    proportional = cfg.lambda_kp * (js_estimate - cfg.lambda_target)
    return float(min(max(integral + proportional, 0.0), cfg.lambda_max))


def _critic_ev(batch: AsorBatch) -> float | None:
    """Explained variance of V(s) against the chunks' discounted returns (bootstrapped with
    V at each chunk's end); None without chunk structure."""
    if (
        batch.chunks is None
        or batch.next_values is None
        or batch.terminateds is None
        or batch.ranked is not None
    ):
        return None
    r = batch.env_rewards.double().tolist()
    nv = batch.next_values.double().tolist()
    term = batch.terminateds.bool().tolist()
    targets = [0.0] * len(r)
    for chunk in batch.chunks:
        g = 0.0
        for t in range(chunk.stop - 1, chunk.start - 1, -1):
            nxt = nv[t] if t == chunk.stop - 1 else g
            g = r[t] + batch.gamma * (0.0 if term[t] else nxt)
            targets[t] = g
    values = batch.values.double()
    return explained_variance(values, torch.tensor(targets, dtype=torch.float64, device=values.device))


def _archive_episodes(archive: StateArchive, batch: AsorBatch) -> None:
    term = batch.terminateds
    for chunk in batch.chunks or ():
        archive.add_chunk(
            chunk.key,
            batch.features[chunk.start : chunk.stop],
            batch.env_rewards[chunk.start : chunk.stop],
            chunk.dynamics_id,
            terminated=bool(term[chunk.stop - 1]) if term is not None else False,
            gamma=batch.gamma,
        )
    archive.end_call(batch.gamma)


def _warn_once(message: str, _seen: set[str] = set()) -> None:  # noqa: B006 - a cache
    if message not in _seen:
        _seen.add(message)
        logger.warning(message)


def _torch_generator(rng: np.random.Generator) -> torch.Generator:
    return torch.Generator().manual_seed(int(rng.integers(0, 2**31 - 1)))


def _metrics(
    state: AsorState,
    lam: float,
    scale: float,
    bonus: torch.Tensor,
    delta: torch.Tensor,
    logits: torch.Tensor,
    batch: AsorBatch,
    batch_real: torch.Tensor,
    labels: torch.Tensor,
) -> dict[str, Any]:
    if delta.numel() == 0:
        return {}
    omega = torch.sigmoid(logits)
    env_r = batch.env_rewards.float()
    stats: dict[str, Any] = {
        "lambda": lam,
        "reward_scale": scale,
        "real_fraction": float(labels.mean()) if labels.numel() else 0.0,
        "aug_reward_mean": float(delta.mean()),
        "aug_reward_min": float(delta.min()),
        "aug_reward_max": float(delta.max()),
        "aug_reward_abs_mean": float(delta.abs().mean()),
        "bonus_mean": float(bonus.mean()),
        "env_reward_mean": float(env_r.mean()),
        "value_mean": float(batch.values.mean()),
        "omega_batch_mean": float(omega.mean()),
    }
    if batch_real.any():
        stats["omega_real_mean"] = float(omega[batch_real].mean())
        stats["value_real_mean"] = float(batch.values[batch_real].mean())
    if not batch_real.all():
        stats["omega_generated_mean"] = float(omega[~batch_real].mean())
    if state.archive is not None:
        stats["archive_states"] = float(len(state.archive))
    return stats
