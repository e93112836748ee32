"""`BcoConfig` / `BCO`: BCO as an RLlib algorithm (module docstring of `rllib_asor.algorithms.bco`).

    from rllib_asor import BcoConfig
    config = (BcoConfig()
              .environment("rllib_asor/LavaWorld-v0")
              .bco(demonstrations="lava-expert.npz", alpha=0.1, pre_demo_steps=2000))
    algo = config.build_algo(); algo.train()                  # BCO(0.1), online
    offline = (BcoConfig().environment("rllib_asor/HopperShift-v0")
               .offline_data(input_=["data/offline/hopper/original/medium"])
               .bco(demonstrations="data/offline/hopper"))     # offline: the data's own (s, a, s')

The policy is RLlib's default BC RLModule trained by `BcoTorchLearner` (one Learner or several);
the inverse dynamics model (`IdmTrainer`) lives on the driver, beside the env runners whose
transitions it learns from, and its state is part of the Algorithm's checkpoints.
"""

from __future__ import annotations

import os
from typing import Any

import gymnasium as gym
import numpy as np
from ray.rllib.algorithms.algorithm import Algorithm
from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.columns import Columns
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.execution.rollout_ops import synchronous_parallel_sample
from ray.rllib.policy.sample_batch import MultiAgentBatch, SampleBatch
from ray.rllib.utils.metrics import (
    ENV_RUNNER_RESULTS,
    LEARNER_RESULTS,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
)

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.bco.learner import BcoTorchLearner
from rllib_asor.algorithms.bco.settings import BcoSettings
from rllib_asor.algorithms.common.demonstrations import load_demonstrations, resolve_path
from rllib_asor.algorithms.common.ifo_data import (
    dataset_transitions,
    evaluate_on_data,
    offline_parts,
)
from rllib_asor.algorithms.common.inverse_dynamics import IdmTrainer

NO_DEMOS = (
    "BCO needs expert demonstrations: set bco.demonstrations (YAML) or "
    "BcoConfig().bco(demonstrations=PATH) to an .npz of state-only transitions or a "
    "`rllib data collect` dataset dir"
)
STATE_KEY = "bco_inverse_dynamics"
"""Key of the inverse dynamics model's state (and the labels) in the Algorithm's state."""
METRICS_KEY = "bco"
"""Where the model's statistics go in the results (`bco/idm_loss`, ...)."""


class BcoConfig(AlgorithmConfig):
    """BCO's AlgorithmConfig; its own settings: `.bco(**settings)` (`BcoSettings`, the YAML
    `bco:` block). `lr` and `train_batch_size_per_learner` are behavioural cloning's."""

    def __init__(self, algo_class: type | None = None) -> None:
        super().__init__(algo_class=algo_class or BCO)
        self.bco_settings: dict[str, Any] = BcoSettings().to_dict()
        self.lr = 1e-3
        self.train_batch_size_per_learner = 64
        self.num_env_runners = 0
        self.min_time_s_per_iteration = None
        self.min_sample_timesteps_per_iteration = 0
        self.min_train_timesteps_per_iteration = 0

    def bco(self, **settings: Any) -> BcoConfig:
        """Set BCO's settings (fields of `BcoSettings`; `demonstrations` a path, made absolute
        here); ValueError names a bad key/value."""
        path = settings.get("demonstrations")
        if isinstance(path, os.PathLike | str):
            settings["demonstrations"] = os.path.abspath(os.fspath(path))
        self.bco_settings = BcoSettings.from_dict({**self.bco_settings, **settings}).to_dict()
        return self

    @property
    def is_offline(self) -> bool:
        # BCO reads its data itself (whole episodes, for s′); RLlib's Ray Data reader must not run.
        return False

    def get_default_rl_module_spec(self) -> RLModuleSpec:
        from ray.rllib.algorithms.bc.torch.default_bc_torch_rl_module import (
            DefaultBCTorchRLModule,
        )

        return RLModuleSpec(module_class=DefaultBCTorchRLModule)

    def get_default_learner_class(self) -> type:
        return BcoTorchLearner

    def validate(self) -> None:
        super().validate()
        if self.framework_str != "torch":
            raise ValueError(f"BCO needs framework='torch', got {self.framework_str!r}")
        settings = BcoSettings.from_dict(self.bco_settings)
        if not settings.demonstrations:
            raise ValueError(NO_DEMOS)
        path = resolve_path(settings.demonstrations)
        if os.path.exists(path) and isinstance(self.env, str) and self.env in gym.registry:
            env = gym.make(self.env, **dict(self.env_config or {}))
            try:
                space = env.observation_space
            finally:
                env.close()
            load_demonstrations(path, space)  # missing ones: the CLI's and setup's error


class BCO(Algorithm):
    """BCO(α) online, BCO on a dataset offline (`rllib_asor.algorithms.bco`)."""

    @classmethod
    def get_default_config(cls) -> BcoConfig:
        return BcoConfig()

    def setup(self, config: Any) -> None:
        super().setup(config)
        s = BcoSettings.from_dict(self.config.bco_settings)
        self._settings = s
        obs_space, act_space = self._spaces()
        self._demos = load_demonstrations(resolve_path(s.demonstrations), obs_space)
        self._act_space = act_space
        self.idm = IdmTrainer(
            int(np.prod(obs_space.shape)),
            act_space,
            hiddens=s.idm_hiddens,
            lr=s.idm_lr,
            steps=s.idm_steps,
            batch_size=s.idm_batch_size,
            capacity=s.idm_capacity,
            seed=s.seed,
        )
        self._parts = offline_parts(self.config)
        self._labels: np.ndarray | None = None

    def _spaces(self) -> tuple[gym.Space, gym.Space]:
        spaces = getattr(self, "spaces", None) or {}
        pair = spaces.get(DEFAULT_MODULE_ID) or spaces.get("__env__")
        if pair is None or pair[0] is None:
            env = gym.make(self.config.env, **dict(self.config.env_config or {}))
            try:
                return env.observation_space, env.action_space
            finally:
                env.close()
        return pair[0], pair[1]

    # ---------------------------------------------------------------------- one iteration
    def training_step(self) -> None:
        s = self._settings
        it = self.iteration  # iterations completed before this one
        new = 0
        if self._parts:
            if len(self.idm) == 0:  # offline: the dataset's own transitions, once
                obs, act, nxt = dataset_transitions(self._parts)
                self.idm.add(obs, self._clip(act), nxt)
                new = len(obs)
        else:
            steps = s.pre_demo_steps if it == 0 else int(round(s.alpha * s.pre_demo_steps))
            if steps > 0:
                new = self._sample(steps, random_actions=it == 0)
        stats: dict[str, float] = {}
        if new or self._labels is None:
            stats = self.idm.update()
            self._labels = self.idm.infer(self._demos.obs, self._demos.next_obs).cpu().numpy()
        n = len(self._demos)
        batch = MultiAgentBatch(
            {
                DEFAULT_MODULE_ID: SampleBatch(
                    {Columns.OBS: self._demos.obs, Columns.ACTIONS: self._labels}
                )
            },
            env_steps=n,
        )
        results = self.learner_group.update(
            batch=batch,
            timesteps={
                NUM_ENV_STEPS_SAMPLED_LIFETIME: self.metrics.peek(
                    (ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME), default=0
                )
            },
            num_epochs=s.bc_epochs,
            minibatch_size=int(self.config.train_batch_size_per_learner),
        )
        self.metrics.aggregate(results, key=LEARNER_RESULTS)
        if not self._parts and self.env_runner_group is not None:
            self.env_runner_group.sync_weights(
                from_worker_or_learner_group=self.learner_group, inference_only=True
            )
        self.metrics.log_dict(
            {**stats, "new_transitions": float(new), "demo_transitions": float(n)},
            key=METRICS_KEY,
            window=1,
        )
        if self._parts and s.evaluation_interval and (it + 1) % s.evaluation_interval == 0:
            flat = evaluate_on_data(self, s.evaluation_episodes)
            if flat:
                self.metrics.log_dict(flat, key="evaluation", window=1)

    def _sample(self, steps: int, random_actions: bool) -> int:
        """`steps` env steps (random actions, or the policy's samples) into the model's buffer;
        how many transitions were added."""
        episodes, runner_results = synchronous_parallel_sample(
            worker_set=self.env_runner_group,
            max_env_steps=steps,
            sample_timeout_s=self.config.sample_timeout_s,
            random_actions=random_actions,
            _uses_new_env_runners=True,
            _return_metrics=True,
        )
        self.metrics.aggregate(runner_results, key=ENV_RUNNER_RESULTS)
        added = 0
        for ep in episodes:
            obs = np.asarray(ep.get_observations(), dtype=np.float32)
            act = np.asarray(ep.get_actions())
            if len(act) == 0:
                continue
            self.idm.add(obs[:-1], self._clip(act), obs[1:])
            added += len(act)
        return added

    def _clip(self, actions: np.ndarray) -> np.ndarray:
        """Box actions clipped to the space (what the env ran; a Gaussian samples outside)."""
        if isinstance(self._act_space, gym.spaces.Box):
            flat = np.asarray(actions, np.float32).reshape(len(actions), -1)
            low, high = self._act_space.low.reshape(-1), self._act_space.high.reshape(-1)
            return np.clip(flat, low, high)
        return np.asarray(actions)

    # ---------------------------------------------------------------------- checkpoints
    def get_state(
        self, components: Any = None, *, not_components: Any = None, **kwargs: Any
    ) -> dict[str, Any]:
        """RLlib's state plus the inverse dynamics model (weights, optimizer, buffer) and the
        current labels of the demonstrations."""
        state = super().get_state(components, not_components=not_components, **kwargs)
        if compat.wants_component(self, STATE_KEY, components, not_components):
            state[STATE_KEY] = {"idm": self.idm.get_state(), "labels": self._labels}
        return state

    def set_state(self, state: dict[str, Any]) -> None:
        super().set_state(state)
        saved = state.get(STATE_KEY)
        if saved is not None:
            self.idm.set_state(saved["idm"])
            self._labels = saved["labels"]
