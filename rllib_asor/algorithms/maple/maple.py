"""`MapleConfig` / `MAPLE` (and `MopoConfig` / `MOPO`): model-based offline RL on RLlib's new stack.

One training iteration = one epoch of the torch port's loop (`AIDefender/SRPO
offlinerl/algo/modelbase/maple_st.py AlgoTrainer.train`):

1. (setup, once) read the dataset parts (`config.input_`, the `rllib data collect` layout) in
   trajectory order; train the dynamics ensemble, or load it from the cache keyed by dataset,
   ensemble settings and seed (paired runs share it); the clip ranges from the data;
2. every `hidden_refresh_every` iterations, recompute the real segments' starting hidden
   states with the current GRUs (`loader.reset_hidden_state`);
3. roll the model out from `rollout_batch_size` dataset states (`rollout.model_rollout`) into
   the model pool;
4. `steps_per_iteration` SAC steps (`learner_group.update(batch=...)`, one 256-segment batch
   each, 5 % real / 95 % model); each batch also carries 256 flat real transitions (`real_*`
   columns) that extensions may use (the ASOR glue ranks and discriminates them);
5. every `evaluation_interval` iterations, the deterministic policy under each dynamics of the
   dataset, D4RL-normalised (`evaluation.evaluate`), in the result under `evaluation/`.

The trajectory-ordered data and the pools live in numpy on the driver (BASES.md); the
networks, the ensemble and the data statistics live in the RLModule, so a checkpoint brings all
of them back, with the driver's random generator (and, with `checkpoint_model_pool`, the model
pool: otherwise a restored run refills it with its next rollouts).
"""

from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path
from typing import Any

import numpy as np
import torch
from ray.rllib.algorithms.algorithm import Algorithm
from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch
from ray.rllib.utils.metrics import LEARNER_RESULTS

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.maple.data import load_trajectories
from rllib_asor.algorithms.maple.ensemble import (
    GaussianEnsemble,
    cache_path,
    dataset_key,
    load_ensemble,
    save_ensemble,
    train_ensemble,
)
from rllib_asor.algorithms.maple.evaluation import evaluate
from rllib_asor.algorithms.maple.rollout import clip_range, model_rollout
from rllib_asor.algorithms.maple.segments import (
    RealSegments,
    SegmentPool,
    episode_hiddens,
    mixed_batch,
)
from rllib_asor.algorithms.maple.settings import (
    MOPO_DEFAULTS,
    MapleSettings,
    expand_ensemble,
    mopo_dataset_settings,
)
from rllib_asor.algorithms.maple.termination import termination_fn

logger = logging.getLogger(__name__)

SAMPLER_STATE = "maple_sampler"
"""The key of the driver's sampler (random generator, model pool) in the algorithm's state."""

REAL_PREFIX = "real_"
"""Columns of the flat real transitions each SAC batch carries (`real_obs`, ...)."""


class MapleConfig(AlgorithmConfig):
    """MAPLE's AlgorithmConfig. Its own settings: `.maple(**settings)` (`MapleSettings`, the
    YAML `maple:` block); the data: `.offline_data(input_=[part dirs])`, e.g.
    `data/offline/hopper/original/medium` for each dynamics (all parts are mixed).

        config = (MapleConfig().environment("rllib_asor/HopperShift-v0")
                  .offline_data(input_=[".../original/medium", ".../body_mass/medium",
                                        ".../density_10/medium"])
                  .maple(horizon=10, penalty_coef=0.25))
        algo = config.build_algo(); algo.train()
    """

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or MAPLE)
        self.maple_settings: dict[str, Any] = MapleSettings().to_dict()
        self.dara_settings: dict[str, Any] | None = None
        """DARA's reward correction of the source rows (`rllib_asor.with_dara`, the YAML `dara:`
        block; rllib_asor/algorithms/dara); None: off."""
        self.gamma = 0.99
        self.lr = None  # each optimizer has its own (maple.actor_lr, critic_lr, alpha_lr)
        self.train_batch_size_per_learner = 256
        self.num_env_runners = 0
        self.min_time_s_per_iteration = None
        self.min_sample_timesteps_per_iteration = 0
        self.min_train_timesteps_per_iteration = 0

    def maple(self, **settings: Any) -> MapleConfig:
        """Set MAPLE settings (merged into the current ones, validated at once; an
        `ensemble` preset name is expanded first)."""
        merged = {**self.maple_settings, **expand_ensemble(settings)}
        self.maple_settings = MapleSettings.from_dict(merged).to_dict()
        return self

    def update_from_dict(self, config_dict: dict[str, Any]) -> MapleConfig:
        """RLlib's, except that `maple_settings` (the YAML `maple:` block) is merged into the
        current settings (a MOPO config keeps its defaults under a partial block)."""
        config_dict = dict(config_dict)
        block = config_dict.pop("maple_settings", None)
        super().update_from_dict(config_dict)
        if block is not None:
            self.maple(**block)
        return self

    @property
    def settings(self) -> MapleSettings:
        return MapleSettings.from_dict(self.maple_settings)

    @property
    def is_offline(self) -> bool:
        # MAPLE reads its data itself (trajectory order); RLlib's Ray Data reader must not start.
        return False

    @property
    def _model_config_auto_includes(self) -> dict[str, Any]:
        return super()._model_config_auto_includes | {"maple": dict(self.maple_settings)}

    def get_default_rl_module_spec(self) -> RLModuleSpec:
        from rllib_asor.algorithms.maple.module import MapleTorchRLModule

        return RLModuleSpec(module_class=MapleTorchRLModule)

    def get_default_learner_class(self) -> type:
        from rllib_asor.algorithms.maple.learner import MapleTorchLearner

        return MapleTorchLearner

    def validate(self) -> None:
        super().validate()
        MapleSettings.from_dict(self.maple_settings)
        if self.dara_settings is not None:
            from rllib_asor.algorithms.dara.settings import DaraSettings

            DaraSettings.from_dict(self.dara_settings)
        if self.framework_str != "torch":
            raise ValueError(f"MAPLE needs framework='torch', got {self.framework_str!r}")
        if not data_paths(self):
            raise ValueError(
                "MAPLE needs offline data: config.offline_data(input_=[part dirs such as "
                "'data/offline/hopper/original/medium']); make it with `make datasets`"
            )


class MopoConfig(MapleConfig):
    """MOPO: MAPLE with the context switched off (no GRU). h and λ_u are MOPO's own for the
    dataset (`settings.MOPO_DATASETS`, e.g. hopper medium: h 5, λ 5) unless set here; h 5,
    λ 1 for data MOPO has no setting for."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or MOPO)
        self.maple(**MOPO_DEFAULTS)
        self.mopo_user_keys: list[str] = []
        """The `maple` keys the user set (those the dataset's MOPO setting leaves alone)."""

    def maple(self, **settings: Any) -> MopoConfig:
        if hasattr(self, "mopo_user_keys"):
            self.mopo_user_keys = sorted({*self.mopo_user_keys, *settings})
        return super().maple(**settings)

    def update_from_dict(self, config_dict: dict[str, Any]) -> MopoConfig:
        """MapleConfig's; a dict of a whole config (`to_dict()`) keeps its own user keys."""
        user = config_dict.get("mopo_user_keys")
        super().update_from_dict(config_dict)
        if user is not None:
            self.mopo_user_keys = sorted(user)
        return self

    @property
    def settings(self) -> MapleSettings:
        return MapleSettings.from_dict(self._mopo_settings())

    def _mopo_settings(self) -> dict[str, Any]:
        per_dataset = mopo_dataset_settings(data_paths(self))
        keep = set(self.mopo_user_keys)
        return {**self.maple_settings, **{k: v for k, v in per_dataset.items() if k not in keep}}

    @property
    def _model_config_auto_includes(self) -> dict[str, Any]:
        return super()._model_config_auto_includes | {"maple": self._mopo_settings()}


def data_paths(config: AlgorithmConfig) -> list[str]:
    """The dataset part dirs of `config.input_` (a str or a list of str)."""
    value = config.input_
    if isinstance(value, str) and value != "sampler":
        return [value]
    if isinstance(value, list) and all(isinstance(v, str) for v in value):
        return list(value)
    return []


def _manifest(paths: list[str]) -> dict[str, Any] | None:
    """The task's manifest when the parts sit in a `rllib data collect` task dir."""
    root = Path(paths[0]).parent.parent / "manifest.json"
    return json.loads(root.read_text()) if root.is_file() else None


class MAPLE(Algorithm):
    """MAPLE (Chen et al., NeurIPS 2021) on RLlib's new stack; see the module docstring."""

    @classmethod
    def get_default_config(cls) -> MapleConfig:
        return MapleConfig()

    def setup(self, config: Any) -> None:
        super().setup(config)
        s = self.config.settings
        self._settings = s
        self._rng = np.random.default_rng(self.config.seed)
        paths = data_paths(self.config)
        missing = [p for p in paths if not Path(p).is_dir()]
        if missing:
            raise ValueError(
                f"MAPLE: offline input {missing[0]} does not exist; make the data first: "
                "`make datasets` (docs/offline.md)"
            )
        self._dara_info: dict[str, float] = {}
        if self.config.dara_settings is not None:  # DARA: train on the relabelled copies
            from rllib_asor.algorithms.dara.relabel import dara_parts

            seed = int(self.config.seed or 0)
            paths, self._dara_info = dara_parts(paths, self.config.dara_settings, seed)
        self._paths = paths
        self._manifest = _manifest(paths)
        t0 = time.perf_counter()
        self._traj = load_trajectories(paths)
        self._env_id = str(self.config.env)
        self._terminated = termination_fn(self._env_id)
        self._limits = clip_range(
            self._traj.obs, self._traj.rewards, s.penalty_coef, s.penalty_clip, floor=s.clip_floor
        )
        self._ensemble_info = self._ensemble(s)
        lim = self._limits

        def set_stats(learner: Any) -> None:
            m = learner.module[DEFAULT_MODULE_ID].unwrapped()
            m.obs_lo.copy_(torch.as_tensor(lim.obs_lo, device=m.obs_lo.device))
            m.obs_hi.copy_(torch.as_tensor(lim.obs_hi, device=m.obs_hi.device))
            rew = [lim.rew_lo, lim.rew_hi]
            m.reward_range.copy_(torch.tensor(rew, device=m.reward_range.device))

        self.learner_group.foreach_learner(set_stats)
        dims = (s.gru_hidden if s.context else 0,) * 2
        self._real = RealSegments(self._traj, s.horizon, dims)
        self._refresh_hiddens()
        self._pool = SegmentPool(s.model_pool_size)
        self._setup_seconds = time.perf_counter() - t0

    # ------------------------------------------------------------------------- the model
    def _ensemble(self, s: MapleSettings) -> dict[str, Any]:
        """Load the cached ensemble of (dataset, settings, seed) or train and cache it; copy it
        into the Learners' modules."""
        keys = [k for k in s.to_dict() if k.startswith("ensemble_") and k != "ensemble_cache"]
        ens_settings = {k: s.to_dict()[k] for k in keys}
        seed = int(self.config.seed or 0)
        path = None
        if s.ensemble_cache:
            key = dataset_key(self._paths, ens_settings)
            path = cache_path(os.path.expanduser(s.ensemble_cache), key, seed)
        t = self._traj
        if path is not None and path.is_file():
            model, report = load_ensemble(path)
            info = {"cached": 1.0, "path": str(path)}
        else:
            with torch.random.fork_rng():
                torch.manual_seed(seed)
                model = GaussianEnsemble(
                    t.obs.shape[1],
                    t.actions.shape[1],
                    s.ensemble_members,
                    s.ensemble_elites,
                    s.ensemble_hidden,
                    s.ensemble_layers,
                )
                rep = train_ensemble(
                    model,
                    t.obs,
                    t.actions,
                    t.next_obs,
                    t.rewards,
                    seed=seed,
                    batch_size=s.ensemble_batch_size,
                    lr=s.ensemble_lr,
                    weight_decay=s.ensemble_weight_decay,
                    patience=s.ensemble_patience,
                    max_epochs=s.ensemble_max_epochs,
                )
            if path is not None:
                save_ensemble(model, rep, path)
            report = rep.__dict__
            info = {"cached": 0.0, "path": str(path) if path else ""}
        info.update(
            {
                "epochs": float(report["epochs"]),
                "holdout_mse_elites": float(
                    np.mean([report["val_losses"][i] for i in report["elites"]])
                ),
                "train_seconds": float(report["seconds"]),
            }
        )
        state = model.state_dict()

        def load(learner: Any) -> None:
            m = learner.module[DEFAULT_MODULE_ID].unwrapped()
            m.ensemble.load_state_dict(state)
            m.ensemble_ready.fill_(1.0)

        self.learner_group.foreach_learner(load)
        return info

    def _module(self) -> Any:
        """The current MAPLE module on the driver (the local Learner's, or a synced copy)."""
        if self.learner_group.is_local:
            return compat.local_learner(self.learner_group).module[DEFAULT_MODULE_ID].unwrapped()
        if not hasattr(self, "_driver_module"):
            import gymnasium as gym

            import rllib_asor.envs  # noqa: F401  (registers our env ids)
            from rllib_asor.algorithms.maple.module import MapleTorchRLModule

            env = gym.make(self._env_id, **dict(self.config.env_config or {}))
            self._driver_module = RLModuleSpec(
                module_class=MapleTorchRLModule,
                observation_space=env.observation_space,
                action_space=env.action_space,
                model_config=self.config.model_config,
            ).build()
            env.close()
        self._driver_module.set_state(
            self.learner_group.get_weights(module_ids=[DEFAULT_MODULE_ID])[DEFAULT_MODULE_ID]
        )
        return self._driver_module

    def _refresh_hiddens(self) -> None:
        nets = self._module().nets
        if not nets.use_context:
            return
        self._real.set_hiddens(
            episode_hiddens(self._traj, lambda o, a: nets.hidden_sequences("policy", o, a)),
            episode_hiddens(self._traj, lambda o, a: nets.hidden_sequences("value", o, a)),
        )

    def get_state(
        self,
        components: Any = None,
        *,
        not_components: Any = None,
        **kwargs: Any,
    ) -> dict[str, Any]:
        """RLlib's state plus the driver's sampler: its random generator and, with
        `checkpoint_model_pool`, the model pool."""
        state = super().get_state(components, not_components=not_components, **kwargs)
        if compat.wants_component(self, SAMPLER_STATE, components, not_components):
            state[SAMPLER_STATE] = {
                "rng": self._rng.bit_generator.state,
                "pool": self._pool.get_state() if self._settings.checkpoint_model_pool else None,
            }
        return state

    def set_state(self, state: dict[str, Any]) -> None:
        super().set_state(state)
        sampler = state.get(SAMPLER_STATE)
        if sampler is not None:
            self._rng.bit_generator.state = sampler["rng"]
            self._pool = SegmentPool(self._settings.model_pool_size)
            if sampler["pool"] is not None:
                self._pool.set_state(sampler["pool"])
        if hasattr(self, "_real"):  # restored GRUs: the real segments' hidden states anew
            self._refresh_hiddens()

    # ---------------------------------------------------------------------- one iteration
    def training_step(self) -> None:
        s, rng = self._settings, self._rng
        it = self.iteration  # iterations completed before this one
        module = self._module()
        if it > 0 and (it - 1) % s.hidden_refresh_every == 0:
            self._refresh_hiddens()
        t0 = time.perf_counter()
        starts = self._real.sample_starts(s.rollout_batch_size, rng)
        segments, stats = model_rollout(
            module.ensemble,
            lambda o, a, h: module.nets.policy_step(o, a, h),
            starts,
            s.horizon,
            self._terminated,
            self._limits,
            s.penalty_coef,
            s.penalty_clip,
            rng,
        )
        self._pool.add(segments)
        t_roll = time.perf_counter() - t0
        t0 = time.perf_counter()
        bs = int(self.config.train_batch_size_per_learner)
        for _ in range(s.steps_per_iteration):
            batch = mixed_batch(self._real, self._pool, bs, s.real_ratio, rng)
            batch.update(self._real_rows(bs, rng))
            results = self.learner_group.update(
                batch=MultiAgentBatch({DEFAULT_MODULE_ID: SampleBatch(batch)}, env_steps=bs),
                timesteps={"maple_gradient_steps": it * s.steps_per_iteration},
            )
            self.metrics.aggregate(results, key=LEARNER_RESULTS)
        t_train = time.perf_counter() - t0
        self.metrics.log_dict(
            {
                "rollout_uncertainty_mean": stats.uncertainty_mean,
                "rollout_uncertainty_max": stats.uncertainty_max,
                "rollout_valid_fraction": stats.valid_fraction,
                "rollout_terminated_fraction": stats.terminated_fraction,
                "rollout_reward_mean": stats.reward_mean,
                "model_pool_segments": float(len(self._pool)),
                "real_segments": float(len(self._real)),
                "rollout_seconds": t_roll,
                "train_seconds": t_train,
                "gradient_steps_per_s": s.steps_per_iteration / max(t_train, 1e-9),
                **{f"ensemble_{k}": v for k, v in self._ensemble_info.items() if k != "path"},
            },
            key="maple",
            window=1,
        )
        self.metrics.log_value("num_gradient_steps_lifetime", s.steps_per_iteration, reduce="sum")
        if self._dara_info:
            self.metrics.log_dict(self._dara_info, key="dara", window=1)
        if s.evaluation_interval and (it + 1) % s.evaluation_interval == 0:
            self._evaluate(module)

    def _real_rows(self, n: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
        """`n` flat real transitions with their hidden states (the `real_*` columns)."""
        t = self._traj
        rows = rng.integers(0, len(t), size=n)
        cols = {
            "obs": t.obs[rows],
            "next_obs": t.next_obs[rows],
            "actions": t.actions[rows],
            "last_actions": t.last_actions[rows],
            "rewards": t.rewards[rows],
            "terminateds": t.terminateds[rows],
            "dynamics_ids": t.dynamics_ids[rows],
            **{k: v[rows] for k, v in self._real.hidden.items()},
        }
        return {REAL_PREFIX + k: v for k, v in cols.items()}

    def _evaluate(self, module: Any) -> None:
        if self._manifest is None:
            return
        s = self._settings
        t0 = time.perf_counter()
        res = evaluate(module.nets, self._manifest, episodes=s.evaluation_episodes, seed=10_000)
        # Without the dataset's reference returns there is no normalized score: absent, not NaN.
        flat = {
            f"{dyn}/{k}": v
            for dyn, stats in res.items()
            for k, v in stats.items()
            if np.isfinite(v)
        }
        flat["seconds"] = time.perf_counter() - t0
        self.metrics.log_dict(flat, key="evaluation", window=1)


class MOPO(MAPLE):
    """MOPO (Yu et al., 2020) as MAPLE with the context switched off (`MopoConfig`)."""

    @classmethod
    def get_default_config(cls) -> MopoConfig:
        return MopoConfig()
