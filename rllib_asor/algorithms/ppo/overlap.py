"""PPO whose env runners sample the next batch while the Learner trains on this one.

RLlib's PPO alternates: the env runners sample a train batch, then wait while the Learner runs
its epochs on it. On a small machine both take about half of an iteration (the race on 2 cores:
docs/results.md, race PPO speed), so the runners' cores idle half the time. `OverlappedPPO`
asks the runners for batch k+1 before it trains on batch k; batch k+1 is therefore sampled with
the weights of one update earlier (a policy lag of one iteration, as in IMPALA/APPO's learner
queue, but with PPO's loss unchanged: its clipped ratio is taken against the log-probabilities
stored at sampling time). The lag is corrected by default: `rllib_asor.algorithms.ppo.lag` takes
PPO's ratio against the current weights and weights each row by its truncated importance weight
(decoupled PPO); `learner_config_dict: {lag_correction: false}` trains on the lagged rows as they
are.

Switched on per config, it is plain PPO otherwise:

    config = overlap_sampling(PPOConfig().env_runners(num_env_runners=1) ...)

or in a YAML file `learner_config_dict: {overlap_sampling: true}`. It needs remote env runners
(`num_env_runners` ≥ 1); with none it samples in the driver as usual. Counting by agent steps is
left to RLlib's PPO.
"""

from __future__ import annotations

import time
from typing import Any

from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.algorithms.ppo import PPO
from ray.rllib.execution.rollout_ops import synchronous_parallel_sample
from ray.rllib.utils.metrics import (
    ALL_MODULES,
    ENV_RUNNER_RESULTS,
    ENV_RUNNER_SAMPLING_TIMER,
    LEARNER_RESULTS,
    LEARNER_UPDATE_TIMER,
    NUM_ENV_STEPS_SAMPLED,
    NUM_ENV_STEPS_SAMPLED_LIFETIME,
    NUM_MODULE_STEPS_TRAINED_LIFETIME,
    SYNCH_WORKER_WEIGHTS_TIMER,
    TIMERS,
)

from rllib_asor.algorithms.ppo.lag import CORRECTION_KEY, WEIGHT_CLIP_KEY, add_correction

OVERLAP_KEY = "overlap_sampling"
"""`learner_config_dict` key that switches the overlap on."""
_TAG = "overlap_sample"


def overlap_enabled(config: AlgorithmConfig) -> bool:
    """Whether `config` asks for overlapped sampling."""
    return bool((config.learner_config_dict or {}).get(OVERLAP_KEY, False))


def overlap_sampling(config: AlgorithmConfig, enabled: bool = True) -> AlgorithmConfig:
    """A copy of the PPO `config` that builds `OverlappedPPO` with the overlap on (or off)."""
    if config.algo_class is None or not issubclass(config.algo_class, PPO):
        name = getattr(config.algo_class, "__name__", type(config).__name__)
        raise ValueError(f"overlap_sampling needs a PPO config, got {name}")
    config = config.copy(copy_frozen=False)
    config.algo_class = OverlappedPPO
    config.learners(
        learner_config_dict={**(config.learner_config_dict or {}), OVERLAP_KEY: enabled}
    )
    return config


class OverlappedPPO(PPO):
    """RLlib's PPO; with `learner_config_dict["overlap_sampling"]` its remote env runners sample
    batch k+1 while the Learner trains on batch k (module docstring)."""

    def setup(self, config: Any) -> None:
        super().setup(config)
        lcd = self.config.learner_config_dict or {}
        if overlap_enabled(self.config) and lcd.get(CORRECTION_KEY, True):
            clip = float(lcd.get(WEIGHT_CLIP_KEY, 1.0))
            self.learner_group.foreach_learner(lambda learner: add_correction(learner, clip))

    def training_step(self) -> None:
        group = self.env_runner_group
        if (
            not overlap_enabled(self.config)
            or self.config.count_steps_by != "env_steps"
            or group is None
            or group.num_healthy_remote_workers() == 0
        ):
            return super().training_step()

        with self.metrics.log_time((TIMERS, ENV_RUNNER_SAMPLING_TIMER)):
            if not group.num_in_flight_async_reqs(_TAG):  # first iteration, restore, failure
                self._launch()
            episodes, runner_metrics = self._collect()
            self._launch()  # the next batch, with the weights the runners hold now
            missing = self.config.total_train_batch_size - sum(
                int(m.get(NUM_ENV_STEPS_SAMPLED, 0)) for m in runner_metrics
            )
            if missing > 0:  # a runner failed or timed out: top up the usual way
                more, more_metrics = synchronous_parallel_sample(
                    worker_set=group,
                    max_env_steps=missing,
                    sample_timeout_s=self.config.sample_timeout_s,
                    _uses_new_env_runners=True,
                    _return_metrics=True,
                )
                episodes += more
                runner_metrics += more_metrics
            if not episodes:
                return
            self.metrics.aggregate(runner_metrics, key=ENV_RUNNER_RESULTS)

        # From here on as RLlib 2.60's PPO.training_step: update, then sync the weights (the
        # sync queues behind the runners' in-flight sample; the batch after it uses them).
        with self.metrics.log_time((TIMERS, LEARNER_UPDATE_TIMER)):
            learner_results = self.learner_group.update(
                episodes=episodes,
                timesteps={
                    NUM_ENV_STEPS_SAMPLED_LIFETIME: self.metrics.peek(
                        (ENV_RUNNER_RESULTS, NUM_ENV_STEPS_SAMPLED_LIFETIME)
                    ),
                    NUM_MODULE_STEPS_TRAINED_LIFETIME: self.metrics.peek(
                        (LEARNER_RESULTS, ALL_MODULES, NUM_MODULE_STEPS_TRAINED_LIFETIME),
                        default=0,
                    ),
                },
                num_epochs=self.config.num_epochs,
                minibatch_size=self.config.minibatch_size,
                shuffle_batch_per_epoch=self.config.shuffle_batch_per_epoch,
            )
            self.metrics.aggregate(learner_results, key=LEARNER_RESULTS)
        with self.metrics.log_time((TIMERS, SYNCH_WORKER_WEIGHTS_TIMER)):
            group.sync_weights(
                from_worker_or_learner_group=self.learner_group,
                policies=set(learner_results[0].keys()) - {ALL_MODULES},
                inference_only=True,
            )

    def _launch(self) -> None:
        """Ask every healthy remote env runner for one sample call (its share of the batch)."""
        self.env_runner_group.foreach_env_runner_async(
            lambda runner: (runner.sample(), runner.get_metrics()), tag=_TAG
        )

    def _collect(self) -> tuple[list[Any], list[dict[str, Any]]]:
        """Wait for the launched sample calls (up to `sample_timeout_s`; failed ones are
        dropped by RLlib's actor manager and topped up by the caller)."""
        group = self.env_runner_group
        episodes: list[Any] = []
        metrics: list[dict[str, Any]] = []
        timeout = self.config.sample_timeout_s
        deadline = None if timeout is None else time.monotonic() + timeout
        while group.num_in_flight_async_reqs(_TAG) > 0:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            for _, (eps, m) in group.fetch_ready_async_reqs(tags=_TAG, timeout_seconds=left):
                episodes += eps
                metrics.append(m)
            if deadline is not None and time.monotonic() >= deadline:
                break
        return episodes, metrics
