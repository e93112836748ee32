"""The ASOR learner-connector piece: partition the train batch and augment its rewards.

Where it must sit: after `NumpyToTensor` and before the advantage / TD-target computation
(PPO: right before `GeneralAdvantageEstimation`), so the critic learns the augmented return
(ALGORITHM.md, Alg. 1 lines 10-11). It sees torch tensors, one dummy step per episode
(`Columns.LOSS_MASK` False, left untouched) and, for stateful modules, `[B, T]` padding.

Per trained policy it
1. takes V(s) from the policy's critic and c(s) from the proxy module (after folding the batch
   into the proxy's normalisers),
2. partitions the valid steps into D_P / D_Q (`rllib_asor.asor.partition`),
3. adds λ·b(s) to the rewards, with b from the discriminator *before* this update's
   discriminator step (the connector runs before the Learner's gradient steps),
4. writes the discriminator's and the proxy's own batches (features + labels), so the Learner
   trains them in the same update.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
import tree
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.core.columns import Columns

from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.discriminator import discriminator_loss
from rllib_asor.asor.encoding import flatten, select, select_space
from rllib_asor.asor.partition import partition
from rllib_asor.asor.reward import dual_ascent_step, reward_bonus, scheduled_lambda
from rllib_asor.rllib.modules import ACTION_FEATURES, DYNAMICS_ID, LABEL

ValueFn = Callable[[Any, dict[str, Any]], torch.Tensor]


@dataclass(frozen=True)
class AuxModuleIds:
    """Module ids of one policy's discriminator and proxy (None when the mode needs none)."""

    disc: str
    proxy: str | None


def critic_values(module: Any, batch: dict[str, Any]) -> torch.Tensor:
    """V(s) from a `ValueFunctionAPI` module (PPO, APPO, IMPALA)."""
    return module.compute_values(batch)


class AddDynamicsIdsToBatch(ConnectorV2):
    """Adds `info["dynamics_id"]` of every step as a batch column (for `rnd_per_dynamics`).

    Sits right after `AddObservationsFromEpisodesToBatch`, so its rows line up with OBS.
    """

    def __call__(self, *, rl_module: Any, batch: dict, episodes: Any, **kwargs: Any) -> Any:
        for episode in self.single_agent_episode_iterator(episodes, agents_that_stepped_only=False):
            infos = episode.get_infos(slice(0, len(episode)))
            if any("dynamics_id" not in info for info in infos):
                raise ValueError(
                    "asor.proxy='rnd_per_dynamics' needs info['dynamics_id'] on every step; "
                    "this env does not report it (use proxy: rnd or ensemble)"
                )
            self.add_n_batch_items(
                batch,
                DYNAMICS_ID,
                items_to_add=[int(info["dynamics_id"]) for info in infos],
                num_items=len(episode),
                single_agent_episode=episode,
            )
        return batch


class AsorRewardConnector(ConnectorV2):
    """Rewrites `rewards += λ·b(s)` and adds the aux modules' batches (see module docstring)."""

    def __init__(
        self,
        input_observation_space: Any = None,
        input_action_space: Any = None,
        *,
        asor: AsorConfig,
        aux_ids: dict[str, AuxModuleIds],
        timestep_fn: Callable[[], float] = lambda: 0.0,
        value_fn: ValueFn = critic_values,
        **kwargs: Any,
    ) -> None:
        super().__init__(input_observation_space, input_action_space, **kwargs)
        self.asor = asor
        self.aux_ids = dict(aux_ids)
        self.timestep_fn = timestep_fn
        self.value_fn = value_fn
        self._rng = np.random.default_rng(asor.seed)
        self.aux_batch_sizes: dict[str, int] = {}
        """Rows of each aux module's batch from the last call (the Learner caps passes)."""

    def __call__(
        self,
        *,
        rl_module: Any,
        batch: dict[str, Any],
        episodes: Any,
        metrics: Any = None,
        **kwargs: Any,
    ) -> Any:
        for policy_id, ids in self.aux_ids.items():
            if policy_id in batch:
                self._augment(rl_module, batch, policy_id, ids, metrics)
        return batch

    # ------------------------------------------------------------------------------------
    def _augment(
        self, rl_module: Any, batch: dict, policy_id: str, ids: AuxModuleIds, metrics: Any
    ) -> None:
        cfg = self.asor
        pb = batch[policy_id]
        policy = rl_module[policy_id].unwrapped()
        rewards = pb[Columns.REWARDS]
        lead, n = rewards.shape, rewards.numel()
        valid = pb.get(Columns.LOSS_MASK)
        valid = (
            torch.ones(n, dtype=torch.bool, device=rewards.device)
            if valid is None
            else valid.reshape(-1).bool()
        )

        def flat_valid(x: Any) -> Any:
            return tree.map_structure(lambda t: t.reshape(n, *t.shape[len(lead) :])[valid], x)

        space = select_space(policy.observation_space, cfg.obs_keys)
        features = flatten(select(flat_valid(pb[Columns.OBS]), cfg.obs_keys), space)
        if not torch.isfinite(features).all():
            bad = (~torch.isfinite(features)).any(-1).sum().item()
            raise ValueError(
                f"ASOR: {bad} observation(s) of policy {policy_id!r} contain NaN/inf; "
                "the reward augmentation needs finite observations (check the env)"
            )
        with torch.no_grad():
            values = self.value_fn(policy, pb).reshape(-1)[valid].float()

        proxy_batch: dict[str, Any] = {Columns.OBS: features}
        counts = None
        if ids.proxy is not None:
            proxy = rl_module[ids.proxy].unwrapped()
            actions = next_features = None
            if cfg.proxy == "ensemble":
                actions = flatten(flat_valid(pb[Columns.ACTIONS]), policy.action_space)
                next_features = flatten(
                    select(flat_valid(pb[Columns.NEXT_OBS]), cfg.obs_keys), space
                )
                proxy_batch.update({ACTION_FEATURES: actions, Columns.NEXT_OBS: next_features})
            dynamics_ids = None
            if cfg.proxy == "rnd_per_dynamics":
                dynamics_ids = flat_valid(pb[DYNAMICS_ID]).long()
                proxy_batch[DYNAMICS_ID] = dynamics_ids
            counts = proxy.update_and_count(features, actions, next_features, dynamics_ids)

        rho_value, rho_count = cfg.effective_rhos
        real = partition(values, counts, rho_value, rho_count, mode=cfg.mode, rng=self._rng)

        disc = rl_module[ids.disc].unwrapped()
        with torch.no_grad():
            logits = disc.logits(features)
            bonus = reward_bonus(logits, cfg.reward_form, cfg.log_omega_min)
            _, disc_stats = discriminator_loss(logits, real.float())
        lam = self._current_lambda(disc, disc_stats["js_estimate"].item())

        added = torch.zeros(n, dtype=rewards.dtype, device=rewards.device)
        added[valid] = (lam * bonus).to(rewards.dtype)
        pb[Columns.REWARDS] = rewards + added.reshape(lead)
        if not torch.isfinite(pb[Columns.REWARDS]).all():
            raise ValueError(
                f"ASOR: rewards of policy {policy_id!r} are NaN/inf after augmentation"
            )

        batch[ids.disc] = {Columns.OBS: features, LABEL: real.float()}
        self.aux_batch_sizes[ids.disc] = features.shape[0]
        if ids.proxy is not None:
            batch[ids.proxy] = proxy_batch
            self.aux_batch_sizes[ids.proxy] = features.shape[0]
        if metrics is not None:
            self._log(
                metrics, ids.disc, lam, bonus, real, values, rewards.reshape(-1)[valid], logits
            )

    def _current_lambda(self, disc: Any, js_estimate: float) -> float:
        """λ for this batch; with "auto", one dual-ascent step on this batch's JS estimate."""
        cfg = self.asor
        if cfg.lambda_ != "auto":
            return scheduled_lambda(cfg.lambda_, self.timestep_fn())
        lam = float(disc.auto_lambda.item())
        disc.auto_lambda.fill_(
            dual_ascent_step(lam, js_estimate, cfg.lambda_target, cfg.lambda_lr, cfg.lambda_max)
        )
        return lam

    @staticmethod
    def _log(
        metrics: Any,
        key: str,
        lam: float,
        bonus: torch.Tensor,
        real: torch.Tensor,
        values: torch.Tensor,
        env_rewards: torch.Tensor,
        logits: torch.Tensor,
    ) -> None:
        if bonus.numel() == 0:
            return
        aug = lam * bonus
        omega = torch.sigmoid(logits)
        stats = {
            "lambda": lam,
            "real_fraction": float(real.float().mean()),
            "aug_reward_mean": float(aug.mean()),
            "aug_reward_min": float(aug.min()),
            "aug_reward_max": float(aug.max()),
            "bonus_mean": float(bonus.mean()),
            "env_reward_mean": float(env_rewards.float().mean()),
            "value_mean": float(values.mean()),
        }
        if real.any():
            stats["omega_real_mean"] = float(omega[real].mean())
            stats["value_real_mean"] = float(values[real].mean())
        if not real.all():
            stats["omega_generated_mean"] = float(omega[~real].mean())
        metrics.log_dict(stats, key=key, window=1)
