"""Fault-tolerance defaults for RLlib configs, and a fault-injecting env for drills.

`with_fault_tolerance(config)` returns a copy of an AlgorithmConfig set up to survive lost
EnvRunners (an env that raises, a worker process that dies, a node that disappears):

- `restart_failed_env_runners=True`: Ray Core restarts the EnvRunner actor (`max_restarts`),
  RLlib re-syncs weights and connector state into it and brings it back into service;
  training goes on with the healthy runners meanwhile.
- `delay_between_env_runner_restarts_s=2`: RLlib's default (60 s) is a `sleep` inside the
  failing actor before it exits, and a synchronous sampling step waits for it: one crashed
  env would stall every PPO iteration for a minute.
- `env_runner_health_probe_timeout_s=5`: while a runner's node is gone, every iteration pings
  it (blocking) before sampling; RLlib's default (30 s) adds 30 s to each such iteration.

What it does not cover (see docs/faults.md): the driver / Learner process itself (resume the
Tune experiment with `rllib train ... --resume`) and the head node.

`FaultInjectionWrapper` + `FaultCounter` reproduce RLlib's own test idiom
(`rllib/algorithms/tests/test_env_runner_failures.py`): an env that raises on chosen EnvRunner
indices after N steps, with a named Ray actor counting across actor restarts so that a
restarted runner does not crash again.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Any

import gymnasium as gym
import ray
from ray.rllib.algorithms.algorithm_config import AlgorithmConfig

# Our defaults (RLlib 2.60's own defaults in comments).
MAX_RESTARTS = 100  # RLlib: 1000
RESTART_DELAY_S = 2.0  # RLlib: 60.0
PROBE_TIMEOUT_S = 5.0  # RLlib: 30.0
FAILURES_TOLERATED = 100  # RLlib: 100 (consecutive failures before the Algorithm gives up)


def with_fault_tolerance(
    config: AlgorithmConfig,
    *,
    max_restarts: int = MAX_RESTARTS,
    restart_delay_s: float = RESTART_DELAY_S,
    probe_timeout_s: float = PROBE_TIMEOUT_S,
    failures_tolerated: int = FAILURES_TOLERATED,
    restart_failed_sub_environments: bool = False,
) -> AlgorithmConfig:
    """Return a copy of `config` that restarts failed EnvRunners quickly.

    `restart_failed_sub_environments=True` additionally re-creates a single crashed
    sub-environment inside a runner instead of restarting the whole runner (the episode in
    progress is lost either way).

    Raises ValueError naming the argument for out-of-range values.
    """
    if not isinstance(config, AlgorithmConfig):
        raise ValueError(
            f"with_fault_tolerance needs an RLlib AlgorithmConfig, got {type(config).__name__}"
        )
    for key, value, low in (
        ("max_restarts", max_restarts, 1),
        ("failures_tolerated", failures_tolerated, 1),
    ):
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{key}={value!r} is invalid: allowed an integer >= {low}")
    for key, value, low in (
        ("restart_delay_s", restart_delay_s, 0.0),
        ("probe_timeout_s", probe_timeout_s, 0.1),
    ):
        if isinstance(value, bool) or not isinstance(value, int | float) or value < low:
            raise ValueError(f"{key}={value!r} is invalid: allowed a number >= {low:g}")
    config = config.copy(copy_frozen=False)
    return config.fault_tolerance(
        restart_failed_env_runners=True,
        max_num_env_runner_restarts=max_restarts,
        delay_between_env_runner_restarts_s=float(restart_delay_s),
        env_runner_health_probe_timeout_s=float(probe_timeout_s),
        num_consecutive_env_runner_failures_tolerance=failures_tolerated,
        restart_failed_sub_environments=restart_failed_sub_environments,
    )


# ------------------------------------------------------------------------------ fault drills
@ray.remote(num_cpus=0)
class FaultCounter:
    """Named actor counting steps and injected faults per EnvRunner; survives runner restarts."""

    def __init__(self) -> None:
        self.steps: dict[int, int] = defaultdict(int)
        self.faults: dict[int, int] = defaultdict(int)

    def step(self, worker_index: int) -> int:
        self.steps[worker_index] += 1
        return self.steps[worker_index]

    def fault(self, worker_index: int) -> int:
        self.faults[worker_index] += 1
        return self.faults[worker_index]

    def stats(self) -> dict[str, dict[int, int]]:
        return {"steps": dict(self.steps), "faults": dict(self.faults)}


class InjectedFault(RuntimeError):
    """The error a `FaultInjectionWrapper` raises on purpose."""


class FaultInjectionWrapper(gym.Wrapper):
    """Raise `InjectedFault` in `step()` on EnvRunner `worker_index`, after `after_steps` steps.

    env_config keys read (besides the wrapped env's own):
      fault_worker_indices: EnvRunner indices that crash (remote runners are 1..N)
      fault_after_steps: steps taken on that runner (all its sub-envs, all restarts) first
      fault_max: faults to inject in total per runner (default 1: the restarted runner is fine)
      fault_counter: name of a `FaultCounter` actor (required)
    """

    def __init__(self, env: gym.Env, env_config: Any) -> None:
        super().__init__(env)
        self.worker_index = int(getattr(env_config, "worker_index", 0))
        self.bad = self.worker_index in set(env_config.get("fault_worker_indices", ()))
        self.after = int(env_config.get("fault_after_steps", 0))
        self.max_faults = int(env_config.get("fault_max", 1))
        self.counter = ray.get_actor(env_config["fault_counter"]) if self.bad else None

    def step(self, action: Any) -> Any:
        if self.counter is not None:
            n = ray.get(self.counter.step.remote(self.worker_index))
            if n > self.after:
                faults = ray.get(self.counter.stats.remote())["faults"].get(self.worker_index, 0)
                if faults >= self.max_faults:
                    self.counter = None  # done: no more round trips to the counter
                else:
                    ray.get(self.counter.fault.remote(self.worker_index))
                    raise InjectedFault(
                        f"injected fault on EnvRunner {self.worker_index} after {n - 1} steps"
                    )
        return self.env.step(action)


def make_faulty_env(env_id: str):
    """An env creator for `tune.register_env`: `env_id` wrapped in FaultInjectionWrapper.

    The keys of FaultInjectionWrapper are removed from the config the wrapped env sees.
    """

    def creator(env_config: Any) -> gym.Env:
        if env_id.startswith("rllib_asor/"):
            import rllib_asor.envs  # noqa: F401  (registers our ids in this process)

        inner = {k: v for k, v in dict(env_config).items() if not k.startswith("fault_")}
        return FaultInjectionWrapper(gym.make(env_id, **inner), env_config)

    return creator
