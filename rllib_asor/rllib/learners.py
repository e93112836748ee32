"""Learner classes with ASOR: the algorithm's own Learner plus the ASOR connector piece.

`AsorLearnerMixin.build()` reads the validated settings from
`config.learner_config_dict["asor"]` (once), finds each trained policy's `AsorModule`, and
builds the one `AsorRewardConnector` with the algorithm's adapter (`asor_adapter`, from
`algorithms/<name>/asor_adapter.py`); it inserts the piece at the adapter's place in the
Learner connector (PPO: right before GAE), or, where train batches bypass that pipeline, the
Learner applies the same piece to its batch (`_apply_asor`). ASOR's networks train inside the
piece (`rllib_asor.asor.trainer.AsorTrainer`, with their own optimisers): RLlib's minibatch
iterator, losses and optimisers see the policy's modules only.

Each ASOR Learner here is the ASOR mixin on exactly the Learner the config uses without ASOR
(RLlib's for a stock config; `LeanPPOTorchLearner`, `FastSACTorchLearner`, ESCP's, MAPLE's
where the config chose them), so an A/B of ASOR compares one Learner with and without ASOR.
"""

from __future__ import annotations

import logging
from typing import Any

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
from ray.rllib.utils.metrics import NUM_ENV_STEPS_SAMPLED_LIFETIME

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.asor_adapter import AsorAdapter
from rllib_asor.algorithms.common.pipeline import insert_beside
from rllib_asor.algorithms.cql.asor_adapter import CQLAsorAdapter
from rllib_asor.algorithms.escp.learner import EscpTorchLearner
from rllib_asor.algorithms.maple.asor_adapter import MapleAsorAdapter
from rllib_asor.algorithms.maple.learner import MapleTorchLearner
from rllib_asor.algorithms.ppo.asor_adapter import PPOAsorAdapter
from rllib_asor.algorithms.ppo.lean import LeanPPOTorchLearner
from rllib_asor.algorithms.sac.asor_adapter import SACAsorAdapter
from rllib_asor.algorithms.sac.learner import FastSACTorchLearner
from rllib_asor.algorithms.sac.replay import MINIBATCH_KEY
from rllib_asor.asor.config import AsorConfig
from rllib_asor.rllib.connector import (
    AddDynamicsIdsToBatch,
    AsorRewardConnector,
    SharedValuesGAE,
)

ASOR_PREFIX = "asor_disc."
"""Module id prefix of ASOR's learner-only module (`rllib.modules.AsorModule`) of a policy.
The name is older than the module: it now holds the discriminator, the proxy and their
optimisers; metrics go under `learners/asor_disc.<policy>/` as before."""


def asor_module_id(policy_id: str) -> str:
    """Module id of the `AsorModule` that belongs to `policy_id`."""
    return ASOR_PREFIX + policy_id


def is_aux_module(module_id: str) -> bool:
    """Whether a module id names one of ASOR's modules."""
    return module_id.startswith(ASOR_PREFIX)


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
            if base is candidate.__bases__[-1]:
                return candidate
        raise ValueError(f"no ASOR Learner on {base.__name__}; allowed: {_bases()}")

    def build(self) -> None:
        super().build()  # type: ignore[misc]
        self.asor = AsorConfig.from_dict(self.config.learner_config_dict.get("asor"))
        self._asor_timestep = 0.0
        ids = {
            pid: asor_module_id(pid)
            for pid in self.module.keys()
            if asor_module_id(pid) in self.module
        }
        if not ids:
            raise ValueError(
                "ASOR learner: no ASOR module found in the MultiRLModule; "
                "build the config with rllib_asor.with_asor(config, ...)"
            )
        in_pipeline = self.asor_adapter.in_pipeline
        self._asor_piece = AsorRewardConnector(
            asor=self.asor,
            module_ids=ids,
            adapter=self.asor_adapter,
            gamma=self.config.gamma,
            minibatch_size=self.asor_minibatch_size(),
            # offline (no env steps): λ's timestep is the rows the piece has ranked
            timestep_fn=(lambda: self._asor_timestep) if in_pipeline else None,
        )
        if in_pipeline:
            self._insert_asor_piece()

    def asor_minibatch_size(self) -> int | None:
        """Rows per step of ASOR's networks: the policy's minibatch size (None: the batch)."""
        size = getattr(self.config, "minibatch_size", None)
        return int(size) if size else None

    def _apply_asor(self, batch: dict[str, Any], aux_rows: float | None = None) -> dict[str, Any]:
        """The ASOR piece on a train batch that bypassed the Learner connector (the fast
        off-policy path's flat batches, offline dataset batches, MAPLE's batches)."""
        return self._asor_piece(
            rl_module=self.module,
            batch=batch,
            episodes=None,
            metrics=self.metrics,
            aux_rows=aux_rows,
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

    def configure_optimizers_for_module(self, module_id: str, config: Any = None) -> None:
        """No RLlib optimiser for ASOR's module: its trainer holds its own."""
        if not is_aux_module(module_id):
            super().configure_optimizers_for_module(module_id, config)  # type: ignore[misc]


class AsorBatchLearnerMixin(AsorLearnerMixin):
    """For Learners whose train batches bypass the Learner connector (offline CQL, MAPLE): the
    piece runs on each batch at the start of the update, once per batch."""

    def _update(self, batch: dict[str, Any], **kwargs: Any) -> Any:
        return super()._update(self._apply_asor(batch), **kwargs)  # type: ignore[misc]


class AsorPPOTorchLearner(AsorLearnerMixin, PPOTorchLearner):
    """RLlib's PPO Learner with ASOR's reward augmentation before GAE."""

    asor_adapter = PPOAsorAdapter()


class AsorLeanPPOTorchLearner(AsorLearnerMixin, LeanPPOTorchLearner):
    """`LeanPPOTorchLearner` (the race's PPO Learner) with ASOR's reward augmentation before GAE."""

    asor_adapter = PPOAsorAdapter()


class FastSoftQAsorMixin(AsorLearnerMixin):
    """ASOR on the fast off-policy path (SAC, ESCP): the ASOR piece runs on the batch built from
    the flat buffer's columns; ASOR's networks take one minibatch per Learner call unless
    `aux_epochs` is set (a pass over the call's rows would train them on every SAC step,
    doubling its cost: docs/results.md)."""

    asor_adapter: AsorAdapter = SACAsorAdapter()

    def flat_batch_module_ids(self) -> list[str]:
        return [m for m in self.module.keys() if not is_aux_module(m)]

    def asor_minibatch_size(self) -> int | None:
        size = (self.config.learner_config_dict or {}).get(MINIBATCH_KEY)
        return int(size) if size else super().asor_minibatch_size()

    def _flat_batch_hook(self, batch: dict[str, Any]) -> dict[str, Any]:
        one_minibatch = self.asor.aux_epochs is None and self.asor_minibatch_size()
        return self._apply_asor(batch, aux_rows=float(one_minibatch) if one_minibatch else None)


class AsorSACTorchLearner(AsorLearnerMixin, SACTorchLearner):
    """RLlib's SAC Learner with ASOR: the piece ends the Learner connector; with `n_step > 1`
    the bonus is added to the n-step sum once (for s_t), an approximation of
    Σ γ^k λ·b(s_{t+k})."""

    asor_adapter = SACAsorAdapter()


class AsorFastSACTorchLearner(FastSoftQAsorMixin, FastSACTorchLearner):
    """The fast path's SAC Learner (`FastSACConfig`) with ASOR: the piece runs once per Learner
    call on the batch built from the flat buffer's columns."""


class AsorESCPTorchLearner(FastSoftQAsorMixin, EscpTorchLearner):
    """ESCP's Learner with ASOR (the paper's Algorithm 1) on the fast path's batches, built
    from ESCP's replay rows with their windows and task ids; V(s) is ESCP's own
    `state_values` (min Q(s, tanh μ(s, z), z̄_task), SAC's adapter asks the module), and
    r_t += λ·b(s_t) goes in before the TD targets. ESCP's encoder, RMDM and critics are
    untouched."""


class AsorCQLTorchLearner(AsorBatchLearnerMixin, CQLTorchLearner):
    """CQL (offline) with ASOR: dataset batches bypass the Learner connector, so the Learner
    applies the piece to each batch in `_update`, before the losses; λ's timestep is the
    number of dataset rows ranked so far (`algorithms/cql/asor_adapter.py`)."""

    asor_adapter = CQLAsorAdapter()


class AsorMapleTorchLearner(AsorBatchLearnerMixin, MapleTorchLearner):
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
