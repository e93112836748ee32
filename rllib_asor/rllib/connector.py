"""The ASOR learner-connector piece: partition the train batch and augment its rewards.

The one entry point of ASOR for every algorithm (PPO, SAC, CQL, ESCP, MAPLE). What differs
per algorithm is the algorithm's adapter (`algorithms/<name>/asor_adapter.py`,
`rllib_asor.algorithms.common.asor_adapter.AsorAdapter`): which value ranks the states,
which rows are ranked, where the reward goes and where the piece sits.

Where it must sit: after `NumpyToTensor` and before the advantage / TD-target computation
(PPO: right before `GeneralAdvantageEstimation`), so the critic learns the augmented return
(docs/algorithm.md, step 7). It sees torch tensors, one dummy step per episode
(`Columns.LOSS_MASK` False, left untouched) and, for stateful modules, `[B, T]` padding.
Where batches bypass the Learner connector (the fast off-policy path's flat batches, offline
dataset batches, MAPLE's batches), the Learner applies this same piece to its train batch.

Per trained policy it turns the adapter's ranked rows into an `AsorBatch` (flat features of
the valid steps, V(s) from the adapter, the episode chunks) and hands it to the policy's
`AsorTrainer` (`rllib_asor.asor.trainer`, held by its `AsorModule`): one call ranks, computes
λ·b(s) with the discriminator *before* this batch's training, and trains the discriminator
and the proxy. The piece adds λ·b(s) to the rewards (or, for an adapter with a
`bonus_column`, writes λ·b of its bonus rows there). Nothing of ASOR enters the policy's
minibatch loop.

Several Learners (DDP): every Learner runs the same ASOR update on the rows of all Learners
(`gather_batches`), so ASOR's state stays identical on all ranks; each keeps the bonus of its
own rows, trains on an equal share of the aux batches and averages the gradients
(docs/algorithm.md, "Many Learners").
"""

from __future__ import annotations

import contextlib
import dataclasses
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np
import torch
import torch.distributed as dist
import tree
from ray.rllib.connectors.connector_v2 import ConnectorV2
from ray.rllib.connectors.learner import GeneralAdvantageEstimation
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns

from rllib_asor.algorithms.common.asor_adapter import DYNAMICS_ID
from rllib_asor.asor.config import AsorConfig
from rllib_asor.asor.networks import flatten, select, select_space
from rllib_asor.asor.proxy import ProxyInputs
from rllib_asor.asor.update import (
    AsorBatch,
    AsorState,
    Chunk,
    bonus_for_rows,
    concat_batches,
)
from rllib_asor.devices import module_device

SHARED_VALUES = "asor_critic_values"
"""`shared_data` key: {policy id: V(s) of every batch row}, from ASOR's piece for GAE."""


class SharedValuesGAE(GeneralAdvantageEstimation):
    """RLlib's GAE, taking V(s) from ASOR's piece where it ran the same critic on the same rows
    (`shared_data[SHARED_VALUES]`) instead of a second critic pass over the batch (~3 % of a
    race PPO update). Modules ASOR did not rank get their values computed as usual."""

    def __call__(self, *, rl_module: Any, shared_data: dict | None = None, **kwargs: Any) -> Any:
        values = (shared_data or {}).pop(SHARED_VALUES, {})
        with _values_given(rl_module, values):
            return super().__call__(rl_module=rl_module, shared_data=shared_data, **kwargs)


@contextlib.contextmanager
def _values_given(rl_module: Any, values: dict[str, torch.Tensor]) -> Iterator[None]:
    """Within the block, `rl_module[mid].compute_values(batch)` returns `values[mid]` for a batch
    of as many rows (other calls go to the module's own method)."""
    patched = []

    def given(module: Any, vf: torch.Tensor) -> Callable[..., torch.Tensor]:
        def compute_values(batch: dict[str, Any], *args: Any, **kwargs: Any) -> torch.Tensor:
            if not args and not kwargs and len(batch[Columns.REWARDS]) == len(vf):
                return vf
            return type(module).compute_values(module, batch, *args, **kwargs)

        return compute_values

    try:
        for mid, vf in values.items():
            module = rl_module[mid].unwrapped()  # what GAE's foreach_module passes
            module.__dict__["compute_values"] = given(module, vf)
            patched.append(module)
        yield
    finally:
        for module in patched:
            module.__dict__.pop("compute_values", None)


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
        module_ids: dict[str, str],
        adapter: Any,
        gamma: float,
        minibatch_size: int | None = None,
        timestep_fn: Callable[[], float] | None = None,
        **kwargs: Any,
    ) -> None:
        """`module_ids`: policy id → the id of its `AsorModule`; `adapter`: the algorithm's
        `AsorAdapter`; `minibatch_size`: rows per step of ASOR's networks (the policy's
        minibatch size; None: the whole batch); `timestep_fn`: env steps sampled so far
        (λ schedules); None (offline): the number of rows this piece has ranked so far, on
        every Learner (not checkpointed: it restarts at 0 on restore)."""
        super().__init__(input_observation_space, input_action_space, **kwargs)
        self.asor = asor
        self.module_ids = dict(module_ids)
        self.adapter = adapter
        self.timestep_fn = timestep_fn
        self.gamma = float(gamma)
        self.minibatch_size = minibatch_size
        self.rows_ranked = 0

    def __call__(
        self,
        *,
        rl_module: Any,
        batch: dict[str, Any],
        episodes: Any,
        metrics: Any = None,
        shared_data: dict | None = None,
        aux_rows: float | None = None,
        **kwargs: Any,
    ) -> Any:
        """`aux_rows`: rows each ASOR network trains on in this call (None: `aux_epochs`
        passes over its batch)."""
        rank, size = rank_and_size()
        timestep = self.timestep_fn() if self.timestep_fn is not None else float(self.rows_ranked)
        for policy_id, module_id in sorted(self.module_ids.items()):
            # Several Learners: every one takes part in every policy's (collective) update.
            if policy_id in batch or size > 1:
                values = self._augment(
                    rl_module, batch, policy_id, module_id, episodes, metrics, timestep, aux_rows
                )
                if shared_data is not None and values is not None:
                    shared_data.setdefault(SHARED_VALUES, {})[policy_id] = values
        return batch

    # ------------------------------------------------------------------------------------
    def _augment(
        self,
        rl_module: Any,
        batch: dict,
        policy_id: str,
        module_id: str,
        episodes: Any,
        metrics: Any,
        timestep: float,
        aux_rows: float | None,
    ) -> torch.Tensor | None:
        """Augments the rewards of `policy_id` and trains its ASOR networks; returns the
        critic's values of every row when the adapter shares them with GAE (what GAE computes
        next), else None."""
        trainer = rl_module[module_id].unwrapped().trainer
        built = (
            self._asor_batch(
                rl_module, batch, policy_id, episodes, timestep, aux_rows, trainer.shuffle_rng
            )
            if policy_id in batch
            else None
        )
        rank, size = rank_and_size()
        if size == 1:
            whole = built[0]
            result = trainer.rank(whole)
            own_delta = result.reward_delta
        else:  # the same update on every Learner, on all their rows (see `gather_batches`)
            shards = gather_batches(None if built is None else built[0], module_device(trainer))
            present = [b for b in shards if b is not None]
            if not present:
                return None
            whole = concat_batches(present)
            result = trainer.rank(whole)
            offset = sum(b.features.shape[0] for b in shards[:rank] if b is not None)
            own_delta = None
            if built is not None:
                own_delta = result.reward_delta[offset : offset + built[0].features.shape[0]]
        self.rows_ranked += whole.features.shape[0]

        if built is not None:
            pb, column = batch[policy_id], self.adapter.bonus_column
            if column is None:
                self._add_to_rewards(pb, built[1], own_delta)
            else:  # ω of the bonus rows before this batch's training, as the ranked rows'
                pb[column] = bonus_on_rows(
                    self.asor, trainer.state, result.lam, self.adapter.bonus_rows(pb), self.gamma
                )
        trainer.learn(result, whole, self.minibatch_size, aux_rows, share=(rank, size))
        if metrics is not None and result.metrics:
            metrics.log_dict(result.metrics, key=module_id, window=1)
        if built is None or not self.adapter.shares_values_with_gae:
            return None
        return built[2]

    def _asor_batch(
        self,
        rl_module: Any,
        batch: dict,
        policy_id: str,
        episodes: Any,
        timestep: float,
        rank_rows: float | None = None,
        rng: np.random.Generator | None = None,
    ) -> tuple[AsorBatch, torch.Tensor, torch.Tensor]:
        """(`AsorBatch` of the policy's valid ranked rows, those rows' indices, the critic's
        raw values of every ranked row). `rank_rows` (with `rng`): where the discriminator
        trains on fewer rows than a flat off-policy batch holds, only that many rows, drawn
        at random, are ranked (their V(s) and counts; `AsorBatch.ranked`); every row still
        gets the bonus."""
        cfg = self.asor
        policy = rl_module[policy_id].unwrapped()
        ranked = self.adapter.ranked_columns
        pb = batch[policy_id] if ranked is None else ranked(batch[policy_id])
        rewards = pb[Columns.REWARDS]
        lead, n = rewards.shape, rewards.numel()
        mask = pb.get(Columns.LOSS_MASK)
        valid = (
            torch.ones(n, dtype=torch.bool, device=rewards.device)
            if mask is None
            else mask.reshape(-1).bool()
        )
        rows = valid.nonzero().squeeze(-1)

        def flat(x: Any) -> Any:
            return tree.map_structure(lambda t: t.reshape(n, *t.shape[len(lead) :]), x)

        space = select_space(policy.observation_space, cfg.obs_keys)
        all_features = flatten(select(flat(pb[Columns.OBS]), cfg.obs_keys), space)
        features = all_features[rows]
        if not torch.isfinite(features).all():
            bad = (~torch.isfinite(features)).any(-1).sum().item()
            raise ValueError(
                f"ASOR: {bad} observation(s) of policy {policy_id!r} contain NaN/inf; "
                "the reward augmentation needs finite observations (check the env)"
            )
        env_rewards = rewards.reshape(-1)[rows]
        if not torch.isfinite(env_rewards).all():
            bad = int((~torch.isfinite(env_rewards)).sum())
            raise ValueError(
                f"ASOR: {bad} reward(s) of policy {policy_id!r} are NaN/inf; the reward "
                "augmentation needs finite rewards (check the env)"
            )
        subset = _rank_subset(batch[policy_id], n, mask, ranked, rank_rows, rng)
        with torch.no_grad():
            source = batch[policy_id]
            if subset is not None:
                source = {k: v[subset] for k, v in source.items()}
            raw_values = self.adapter.state_values(policy, source)
        all_values = raw_values.reshape(-1).float()
        terminateds = pb.get(Columns.TERMINATEDS)
        terminateds = None if terminateds is None else flat(terminateds).bool()

        next_features = None  # off-policy batches (and PPO with the ensemble proxy) carry s′
        if Columns.NEXT_OBS in pb:
            next_features = flatten(select(flat(pb[Columns.NEXT_OBS]), cfg.obs_keys), space)[rows]
        proxy_in = ProxyInputs(features)
        if cfg.needs_proxy and cfg.proxy == "ensemble":
            proxy_in.actions = flatten(flat(pb[Columns.ACTIONS])[rows], policy.action_space)
            proxy_in.next_features = next_features
        if cfg.needs_proxy and cfg.proxy == "rnd_per_dynamics":
            proxy_in.dynamics_ids = flat(pb[DYNAMICS_ID])[rows].long()

        if subset is not None:  # rows == every row here: the subset indexes them directly
            proxy_in = ProxyInputs(
                *(None if (v := getattr(proxy_in, f.name)) is None else v[subset]
                  for f in dataclasses.fields(ProxyInputs))
            )  # fmt: skip
        asor_batch = AsorBatch(
            features=features,
            env_rewards=env_rewards,
            values=all_values if subset is not None else all_values[rows],
            gamma=self.gamma,
            timestep=timestep,
            proxy_inputs=proxy_in,
            terminateds=None if terminateds is None else terminateds[rows],
            ranked=subset,
        )
        if mask is not None and len(lead) == 1:
            # On-policy (PPO's pipeline adds the loss mask): each chunk ends with a bootstrap
            # row (loss mask False) holding s_T, so the row after a valid one is its next state.
            nxt = rows + 1
            asor_batch.next_features = all_features[nxt]
            asor_batch.next_values = all_values[nxt]
            asor_batch.chunks = self._chunks(episodes, policy_id, valid)
        else:  # off-policy / offline: each row is a transition with its own s′
            asor_batch.next_features = next_features
        return asor_batch, rows, raw_values

    def _add_to_rewards(self, pb: dict, rows: torch.Tensor, delta: torch.Tensor) -> None:
        """rewards[rows] += delta (the valid rows of the policy's batch; both are finite:
        checked in `_asor_batch` and by `asor_update`)."""
        rewards = pb[Columns.REWARDS]
        added = torch.zeros(rewards.numel(), dtype=rewards.dtype, device=rewards.device)
        added[rows] = delta.to(rewards.dtype)
        pb[Columns.REWARDS] = rewards + added.reshape(rewards.shape)

    def _chunks(self, episodes: Any, policy_id: str, valid: torch.Tensor) -> list[Chunk] | None:
        """The batch's episode chunks of `policy_id` in row order (valid-row indices), or None
        when the rows cannot be matched to the episodes (then no archive, no warm-up EV)."""
        if episodes is None:
            return None
        chunks, row, start = [], 0, 0
        for ep in self.single_agent_episode_iterator(episodes, agents_that_stepped_only=False):
            if (ep.module_id or DEFAULT_MODULE_ID) != policy_id:
                continue
            length = len(ep)  # real steps + the bootstrap row
            dyn = int(ep.get_infos(0).get("dynamics_id", 0))
            # RLlib suffixes the learner's copy of the id with "_<i>" per batch; strip it so
            # the chunks of one episode share a key across batches.
            key = (ep.id_.rsplit("_", 1)[0], ep.agent_id)
            chunks.append(Chunk(key, start, start + length - 1, dyn))
            row += length
            start += length - 1
        if row != valid.numel() or start != int(valid.sum()):
            return None
        return chunks


def _rank_subset(
    pb: Any,
    n: int,
    mask: Any,
    ranked_columns: Any,
    rank_rows: float | None,
    rng: np.random.Generator | None,
) -> torch.Tensor | None:
    """Sorted indices of `rank_rows` rows drawn from a flat batch of n transitions (every
    column [n, ...] tensors, no loss mask, the policy's own rows), or None: rank them all."""
    if rank_rows is None or rng is None or mask is not None or ranked_columns is not None:
        return None
    k = int(rank_rows)
    if not 0 < k < n or not isinstance(pb, dict):
        return None
    if not all(isinstance(v, torch.Tensor) and v.shape[:1] == (n,) for v in pb.values()):
        return None
    device = next(iter(pb.values())).device
    return torch.from_numpy(np.sort(rng.choice(n, size=k, replace=False))).to(device)


def bonus_on_rows(
    cfg: AsorConfig, state: AsorState, lam: float, rows: dict[str, Any], gamma: float
) -> torch.Tensor:
    """λ·b of every valid row of `rows` (an adapter's `bonus_rows`: `[..., D]` OBS and
    NEXT_OBS, `[...]` TERMINATEDS and "valid") → `[...]`; padding gets 0 and stays out of the
    batch statistics (`asor.update.bonus_for_rows`)."""
    obs = rows[Columns.OBS]
    mask = rows["valid"].reshape(-1).bool()  # the discriminator sees the valid steps only
    b = bonus_for_rows(
        cfg,
        state,
        lam,
        obs.reshape(-1, obs.shape[-1])[mask],
        rows[Columns.NEXT_OBS].reshape(-1, obs.shape[-1])[mask],
        rows[Columns.TERMINATEDS].reshape(-1)[mask],
        gamma,
    )
    delta = torch.zeros(mask.shape, dtype=b.dtype, device=b.device)
    delta[mask] = b
    if not torch.isfinite(delta).all():
        raise ValueError("ASOR: the reward bonus is NaN/inf")
    return delta.reshape(obs.shape[:-1])


# ------------------------------------------------------------------ several Learners (DDP)
def rank_and_size() -> tuple[int, int]:
    """(rank, world size) of the Learners' process group; (0, 1) when there is none."""
    if dist.is_available() and dist.is_initialized():
        return dist.get_rank(), dist.get_world_size()
    return 0, 1


def _moved(value: Any, device: torch.device | str) -> Any:
    if isinstance(value, torch.Tensor):
        return value.to(device)
    if isinstance(value, AsorBatch | ProxyInputs):
        return dataclasses.replace(
            value,
            **{f.name: _moved(getattr(value, f.name), device) for f in dataclasses.fields(value)},
        )
    return value


def gather_batches(batch: AsorBatch | None, device: torch.device | str) -> list[AsorBatch | None]:
    """Every Learner's batch (None where a Learner has none), in rank order, on `device`.

    A collective: every Learner must call it the same number of times.
    """
    out: list[Any] = [None] * dist.get_world_size()
    dist.all_gather_object(out, None if batch is None else _moved(batch, "cpu"))
    return [None if b is None else _moved(b, device) for b in out]
