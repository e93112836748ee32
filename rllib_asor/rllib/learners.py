"""Learner classes with ASOR: the algorithm's own Learner plus the ASOR connector piece.

`AsorLearnerMixin.build()` reads the validated settings from
`config.learner_config_dict["asor"]`, finds each trained policy's discriminator/proxy modules,
and builds the one `AsorRewardConnector` with the algorithm's adapter (`asor_adapter`, from
`algorithms/<name>/asor_adapter.py`); it inserts the piece at the adapter's place in the
Learner connector (PPO: right before GAE), or, where train batches bypass that pipeline, the
Learner applies the same piece to its batch (`_apply_asor`). It also gives the auxiliary
modules their own Adam optimisers (learning rates from `AsorConfig`, frozen RND target
excluded).

Each ASOR Learner here is the ASOR mixin on exactly the Learner the config uses without ASOR
(RLlib's for a stock config; `LeanPPOTorchLearner`, `FastSACTorchLearner`, ESCP's, MAPLE's
where the config chose them), so an A/B of ASOR compares one Learner with and without ASOR.
"""

from __future__ import annotations

import logging
import math
from typing import Any

import torch
from ray.rllib.algorithms.cql.torch.cql_torch_learner import CQLTorchLearner
from ray.rllib.algorithms.ppo.torch.ppo_torch_learner import PPOTorchLearner
from ray.rllib.algorithms.sac.torch.sac_torch_learner import SACTorchLearner
from ray.rllib.connectors.common.add_observations_from_episodes_to_batch import (
    AddObservationsFromEpisodesToBatch,
)
from ray.rllib.connectors.learner import GeneralAdvantageEstimation
from ray.rllib.connectors.learner.add_next_observations_from_episodes_to_train_batch import (
    AddNextObservationsFromEpisodesToTrainBatch,
)
from ray.rllib.core.columns import Columns
from ray.rllib.core.learner.training_data import TrainingData
from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME
from ray.rllib.utils.minibatch_utils import MiniBatchCyclicIterator

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.asor_adapter import AsorAdapter
from rllib_asor.algorithms.common.ddp import SortedModuleGradientsMixin
from rllib_asor.algorithms.common.pipeline import insert_beside
from rllib_asor.algorithms.cql.asor_adapter import CQLAsorAdapter
from rllib_asor.algorithms.escp.learner import EscpTorchLearner
from rllib_asor.algorithms.maple.asor_adapter import MapleAsorAdapter
from rllib_asor.algorithms.maple.learner import MapleTorchLearner
from rllib_asor.algorithms.ppo.asor_adapter import PPOAsorAdapter
from rllib_asor.algorithms.ppo.lean import LeanPPOTorchLearner
from rllib_asor.algorithms.sac.asor_adapter import SACAsorAdapter
from rllib_asor.algorithms.sac.learner import FastSACLearnerMixin, FastSACTorchLearner
from rllib_asor.algorithms.sac.replay import MINIBATCH_KEY
from rllib_asor.asor.config import AsorConfig
from rllib_asor.rllib.connector import (
    AddDynamicsIdsToBatch,
    AsorRewardConnector,
    AuxModuleIds,
    SharedValuesGAE,
)

DISC_PREFIX = "asor_disc."
PROXY_PREFIX = "asor_proxy."


def disc_module_id(policy_id: str) -> str:
    """Module id of the discriminator that belongs to `policy_id`."""
    return DISC_PREFIX + policy_id


def proxy_module_id(policy_id: str) -> str:
    """Module id of the visitation-count proxy (RND/ensemble) of `policy_id`."""
    return PROXY_PREFIX + policy_id


def is_aux_module(module_id: str) -> bool:
    """Whether a module id names one of ASOR's auxiliary modules."""
    return module_id.startswith((DISC_PREFIX, PROXY_PREFIX))


def policy_minibatches(batch: MultiAgentBatch, num_epochs: int, minibatch_size: int) -> int:
    """How many minibatches RLlib's `MiniBatchCyclicIterator` yields for this batch without
    ASOR's aux modules: until every policy module has covered `num_epochs` passes (0 when the
    batch holds no policy rows). The iterator counts a pass each time a module's rows wrap."""
    needed = 0
    for module_id, module_batch in batch.policy_batches.items():
        if is_aux_module(module_id) or len(module_batch) == 0:
            continue
        rows, step = len(module_batch), minibatch_size
        seq_lens = module_batch.get(SampleBatch.SEQ_LENS)
        if seq_lens is not None:  # time-ranked [B, T] batches are cut along B
            rows, step = len(seq_lens), max(1, int(len(seq_lens) * minibatch_size / rows))
        needed = max(needed, math.ceil(num_epochs * rows / step))
    return needed


logger = logging.getLogger(__name__)


class AsorLearnerMixin:
    """Builds the ASOR piece with the algorithm's adapter and puts it in the Learner's pipeline,
    or applies it to batches that bypass the pipeline; mix in before the algorithm's Learner."""

    asor_adapter: AsorAdapter = PPOAsorAdapter()
    """The algorithm's answers to the piece (which value, which rows, where the reward goes)."""

    @staticmethod
    def asor_learner_on(base: type) -> type:
        """The ASOR Learner of this package that adds ASOR to `base` and nothing else (e.g.
        `drop_bootstrap_rows` moving a PPO+ASOR config onto `LeanPPOTorchLearner`)."""
        for candidate in ASOR_LEARNERS:
            if base in candidate.__bases__:
                return candidate
        raise ValueError(f"no ASOR Learner on {base.__name__}; allowed: {_bases()}")

    def build(self) -> None:
        super().build()  # type: ignore[misc]
        self.asor = AsorConfig.from_dict(self.config.learner_config_dict.get("asor"))
        self._asor_timestep = 0.0
        self._asor_rows_trained = {}
        self._asor_aux_sizes: dict[str, int] = {}
        aux = {
            pid: AuxModuleIds(
                disc=disc_module_id(pid),
                proxy=proxy_module_id(pid) if self.asor.needs_proxy else None,
            )
            for pid in self.module.keys()
            if disc_module_id(pid) in self.module
        }
        if not aux:
            raise ValueError(
                "ASOR learner: no discriminator module found in the MultiRLModule; "
                "build the config with rllib_asor.with_asor(config, ...)"
            )
        in_pipeline = self.asor_adapter.in_pipeline
        self._asor_piece = AsorRewardConnector(
            asor=self.asor,
            aux_ids=aux,
            adapter=self.asor_adapter,
            gamma=self.config.gamma,
            # offline (no env steps): λ's timestep is the rows the piece has ranked
            timestep_fn=(lambda: self._asor_timestep) if in_pipeline else None,
        )
        if in_pipeline:
            self._insert_asor_piece()

    def _apply_asor(self, batch: dict[str, Any]) -> dict[str, Any]:
        """The ASOR piece on a train batch that bypassed the Learner connector (the fast
        off-policy path's flat batches, offline dataset batches, MAPLE's batches)."""
        return self._asor_piece(
            rl_module=self.module, batch=batch, episodes=None, metrics=self.metrics
        )

    def _insert_asor_piece(self) -> None:
        pipeline = compat.learner_connector(self)
        if pipeline is None:
            raise ValueError(
                "ASOR needs the Learner connector pipeline; set num_aggregator_actors_per_learner=0"
            )
        needs_next_obs = self.asor.proxy == "ensemble" and self.asor.needs_proxy
        if needs_next_obs and not any(
            isinstance(c, AddNextObservationsFromEpisodesToTrainBatch) for c in pipeline.connectors
        ):
            insert_beside(
                pipeline,
                AddObservationsFromEpisodesToBatch,
                AddNextObservationsFromEpisodesToTrainBatch(),
                before=False,
            )
        if self.asor.proxy == "rnd_per_dynamics" and self.asor.needs_proxy:
            insert_beside(
                pipeline, AddObservationsFromEpisodesToBatch, AddDynamicsIdsToBatch(), before=False
            )
        before = self.asor_adapter.insert_before
        if before is None:
            pipeline.append(self._asor_piece)
            return
        insert_beside(pipeline, before, self._asor_piece, before=True)
        gae = next((c for c in pipeline.connectors if type(c) is GeneralAdvantageEstimation), None)
        if gae is not None:  # RLlib's own GAE (not a user's subclass): reuse ASOR's critic pass
            shared = SharedValuesGAE(gamma=gae.gamma, lambda_=gae.lambda_)
            pipeline.insert_after(GeneralAdvantageEstimation, shared)
            pipeline.remove(GeneralAdvantageEstimation)

    def before_gradient_based_update(self, *, timesteps: dict[str, Any]) -> None:
        super().before_gradient_based_update(timesteps=timesteps)  # type: ignore[misc]
        self._asor_timestep = float(timesteps.get(NUM_ENV_STEPS_SAMPLED_LIFETIME, 0) or 0)
        self._asor_rows_trained: dict[str, int] = {}

    def _create_iterator_if_necessary(
        self,
        *,
        training_data: TrainingData,
        num_total_minibatches: int = 0,
        num_epochs: int = 1,
        minibatch_size: int | None = None,
        **kwargs: Any,
    ) -> Any:
        """The policy gets exactly the minibatches it would get without ASOR.

        RLlib's iterator runs until *every* module in the batch has covered `num_epochs`
        passes, and the discriminator's batch (archive states + the whole batch) is longer
        than the policy's: left alone, PPO trained the policy for more epochs than asked
        whenever the archive held states (the race: ~4.9 instead of 4). The count is fixed
        here from the policy modules (aux modules are dropped after their own passes in
        `_update`).
        """
        if not training_data.data_iterators:
            batch = self._make_batch_if_necessary(training_data=training_data)  # type: ignore[attr-defined]
            training_data = TrainingData(batch=batch)
            # The aux batches' sizes, read from the batch the piece wrote (`aux_rows`).
            self._asor_aux_sizes = {
                mid: len(mb) for mid, mb in batch.policy_batches.items() if is_aux_module(mid)
            }
            if minibatch_size and not num_total_minibatches:
                num_total_minibatches = policy_minibatches(batch, num_epochs, minibatch_size)
        batch_iter = super()._create_iterator_if_necessary(  # type: ignore[misc]
            training_data=training_data,
            num_total_minibatches=num_total_minibatches,
            num_epochs=num_epochs,
            minibatch_size=minibatch_size,
            **kwargs,
        )
        if self.asor_adapter.in_pipeline and isinstance(batch_iter, MiniBatchCyclicIterator):
            return self._without_finished_aux(batch_iter)
        return batch_iter

    def _without_finished_aux(self, batch_iter: MiniBatchCyclicIterator) -> Any:
        """The iterator's minibatches; an aux module's batch leaves the iterator once it has
        trained on `aux_rows` rows, instead of being sliced (and reshuffled) for every policy
        minibatch after it and dropped in `_update` (~3 % of a race PPO update)."""
        module_batches = compat.iterator_batch(batch_iter).policy_batches
        for minibatch in batch_iter:
            yield minibatch  # `_update` counts the aux rows it trains on
            for module_id in [m for m in module_batches if is_aux_module(m)]:
                if self._asor_rows_trained.get(module_id, 0) >= self.aux_rows(module_id):
                    del module_batches[module_id]
                    # Without a fixed minibatch count the iterator runs until every module it
                    # tracks covered num_epochs: stop tracking the one that left.
                    compat.iterator_covered_epochs(batch_iter).pop(module_id, None)

    def _update(self, batch: dict[str, Any], **kwargs: Any) -> Any:
        if self.asor_adapter.in_pipeline:
            batch = self._cap_aux_passes(batch)
        else:  # the batch bypassed the Learner connector: the piece runs here, once per batch
            batch = self._apply_asor(batch)
        return super()._update(batch, **kwargs)  # type: ignore[misc]

    def _cap_aux_passes(self, batch: dict[str, Any]) -> dict[str, Any]:
        """Drop aux modules from minibatches once they trained on `aux_rows` rows this update."""
        kept = {}
        for module_id, module_batch in batch.items():
            if is_aux_module(module_id):
                done = self._asor_rows_trained.get(module_id, 0)
                if done >= self.aux_rows(module_id):
                    continue
                self._asor_rows_trained[module_id] = done + len(module_batch[Columns.OBS])
            kept[module_id] = module_batch
        return kept

    def aux_rows(self, module_id: str) -> float:
        """Rows the aux module trains on per update: `aux_epochs` passes over its batch (one
        pass when unset)."""
        size = self._asor_aux_sizes.get(module_id, 0)
        return (1.0 if self.asor.aux_epochs is None else self.asor.aux_epochs) * size

    def configure_optimizers_for_module(self, module_id: str, config: Any = None) -> None:
        if not is_aux_module(module_id):
            return super().configure_optimizers_for_module(module_id, config)  # type: ignore[misc]
        asor = AsorConfig.from_dict(self.config.learner_config_dict.get("asor"))
        is_disc = module_id.startswith(DISC_PREFIX)
        lr = asor.disc_lr if is_disc else asor.rnd_lr
        params = [p for p in self.module[module_id].parameters() if p.requires_grad]
        self.register_optimizer(
            module_id=module_id,
            optimizer=torch.optim.Adam(
                params, weight_decay=asor.disc_weight_decay if is_disc else 0.0
            ),
            params=params,
            lr_or_lr_schedule=lr,
        )


class AsorPPOTorchLearner(AsorLearnerMixin, PPOTorchLearner):
    """RLlib's PPO Learner with ASOR's reward augmentation before GAE."""

    asor_adapter = PPOAsorAdapter()


class AsorLeanPPOTorchLearner(AsorLearnerMixin, LeanPPOTorchLearner):
    """`LeanPPOTorchLearner` (the race's PPO Learner) with ASOR's reward augmentation before GAE."""

    asor_adapter = PPOAsorAdapter()


class _SoftQAsorMixin(AsorLearnerMixin, SortedModuleGradientsMixin):
    """SAC-family Learners: V(s) from the critics; aux losses fed to SAC's per-optimizer
    gradient loop (it pops `_temp_losses[(module_id, "<optimizer>_loss")]`), module by module
    in the same order on every Learner (algorithms/common/ddp.py)."""

    asor_adapter: AsorAdapter = SACAsorAdapter()

    def compute_losses(self, *, fwd_out: dict[str, Any], batch: dict[str, Any]) -> dict[str, Any]:
        losses = super().compute_losses(fwd_out=fwd_out, batch=batch)  # type: ignore[misc]
        for module_id, loss in losses.items():
            if is_aux_module(module_id):
                compat.temp_losses(self)[(module_id, "default_optimizer_loss")] = loss
        return losses


class FastSoftQAsorMixin(FastSACLearnerMixin, _SoftQAsorMixin):
    """ASOR on the fast off-policy path (SAC, ESCP): the ASOR piece runs on the batch built from
    the flat buffer's columns; the aux modules take one minibatch per Learner call."""

    def flat_batch_module_ids(self) -> list[str]:
        return [m for m in self.module.keys() if not is_aux_module(m)]

    def _flat_batch_hook(self, batch: dict[str, Any]) -> dict[str, Any]:
        return self._apply_asor(batch)

    def aux_rows(self, module_id: str) -> float:
        """On the fast path (a call = STEPS_PER_CALL gradient steps on replayed rows) the aux
        modules take one minibatch per call unless `aux_epochs` is set: a pass over the call's
        rows would train them on every SAC step, doubling its cost (docs/results.md)."""
        if getattr(self, "_fast_steps", False) and self.asor.aux_epochs is None:
            return float(self.config.learner_config_dict[MINIBATCH_KEY])
        return super().aux_rows(module_id)


class AsorSACTorchLearner(_SoftQAsorMixin, SACTorchLearner):
    """RLlib's SAC Learner with ASOR: the piece ends the Learner connector; with `n_step > 1`
    the bonus is added to the n-step sum once (for s_t), an approximation of
    Σ γ^k λ·b(s_{t+k})."""


class AsorFastSACTorchLearner(FastSoftQAsorMixin, FastSACTorchLearner):
    """The fast path's SAC Learner (`FastSACConfig`) with ASOR: the piece runs once per Learner
    call on the batch built from the flat buffer's columns."""


class AsorESCPTorchLearner(FastSoftQAsorMixin, EscpTorchLearner):
    """ESCP's Learner with ASOR (the paper's Algorithm 1) on the fast path's batches, built
    from ESCP's replay rows with their windows and task ids; V(s) is ESCP's own
    `state_values` (min Q(s, tanh μ(s, z), z̄_task), SAC's adapter asks the module), and
    r_t += λ·b(s_t) goes in before the TD targets. ESCP's encoder, RMDM and critics are
    untouched."""


class AsorCQLTorchLearner(_SoftQAsorMixin, CQLTorchLearner):
    """CQL (offline) with ASOR: dataset batches bypass the Learner connector, so the Learner
    applies the piece to each batch in `_update`, before the losses; λ's timestep is the
    number of dataset rows ranked so far (`algorithms/cql/asor_adapter.py`)."""

    asor_adapter = CQLAsorAdapter()


class AsorMapleTorchLearner(AsorLearnerMixin, MapleTorchLearner):
    """MAPLE's Learner (MOPO's too) with ASOR. MAPLE's batches bypass the Learner connector,
    so the Learner applies the piece to each batch before the SAC step; MAPLE's adapter ranks
    the real transitions (`real_*` columns) by V(s) = min Q(s, π(s)) with their GRU contexts
    and writes λ·b(s) of every segment step (real and model) into `asor_bonus`, which MAPLE's
    loss adds to the rewards. Offline: λ's timestep is the number of real rows ranked so far
    (not checkpointed)."""

    asor_adapter = MapleAsorAdapter()


ASOR_LEARNERS: tuple[type, ...] = (
    AsorPPOTorchLearner,
    AsorLeanPPOTorchLearner,
    AsorSACTorchLearner,
    AsorFastSACTorchLearner,
    AsorESCPTorchLearner,
    AsorCQLTorchLearner,
    AsorMapleTorchLearner,
)
"""Every ASOR Learner: the ASOR mixin on one Learner (the last of its bases)."""


def _bases() -> str:
    return ", ".join(c.__bases__[-1].__name__ for c in ASOR_LEARNERS)
