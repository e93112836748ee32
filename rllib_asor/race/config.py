"""RLlib wiring for the obstacle race (``game_env``): env names, PPO config, race metrics.

- `register_race_envs()` registers two Tune env names:
  ``game_env/ObstacleRace-v0`` (one racer, the gymnasium env) and
  ``game_env/ObstacleRaceMulti-v0`` (N racers, the PettingZoo ParallelEnv wrapped for RLlib).
  ``env_config`` holds the env's keyword arguments (``map_id``, ``course_seed``,
  ``max_episode_steps``, ...; multi-racer also ``num_racers``).
- `race_ppo_config(...)` returns a PPOConfig with the race network (`RaceNetModule`), one
  shared policy ``"shared"`` for all racers in multi-racer mode, and `RaceMetricsCallback`.
  Call `rllib_asor.with_asor(config, obs_keys=RACE_ASOR_OBS_KEYS, ...)` on it afterwards:
  with_asor keeps the callback.
- `RaceMetricsCallback` logs the paper's per-episode metrics as ``race/...`` in the results.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from ray.rllib.algorithms.ppo import PPOConfig
from ray.rllib.callbacks.callbacks import RLlibCallback
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec
from ray.rllib.env.wrappers.pettingzoo_env import ParallelPettingZooEnv
from ray.rllib.policy.policy import PolicySpec

from rllib_asor.algorithms.common.callbacks import add_callbacks
from rllib_asor.algorithms.ppo.lean import LeanPPOTorchLearner
from rllib_asor.race.curriculum import MapCurriculum, map_curriculum_callback
from rllib_asor.race.net import RaceNetModule

SINGLE_ENV = "game_env/ObstacleRace-v0"
"""Tune name of the single-racer env (same as its gymnasium id)."""
MULTI_ENV = "game_env/ObstacleRaceMulti-v0"
"""Tune name of the multi-racer env (RLlib MultiAgentEnv over the PettingZoo ParallelEnv)."""
SHARED_POLICY = "shared"
"""The one policy all racers share in multi-racer mode."""

RACE_METRICS: dict[str, str] = {
    "success_rate": "success",
    "trapped_rate": "trapped",
    "unnecessary_jump_rate": "unnecessary_jump_rate",
    "distance_from_cliff": "distance_from_cliff",
    "goal_reward": "goal_reward",
}
"""``race/<name>`` ← ``info["episode_metrics"][<key>]`` (one value per racer and episode)."""
RACE_ASOR_OBS_KEYS: list[str] = ["agent", "destination"]
"""Observation keys ASOR's discriminator and RND see on the race (41 dense floats; why:
docs/race_training.md). Pass as `with_asor(config, obs_keys=RACE_ASOR_OBS_KEYS, ...)`."""
METRICS_WINDOW = 100
"""Racer-episodes each ``race/...`` mean is taken over."""


# ---------------------------------------------------------------------- envs
def make_single_race_env(env_config: Mapping[str, Any] | None = None) -> gym.Env:
    """`gymnasium.make("game_env/ObstacleRace-v0", **env_config)` (Tune env creator).

    ``max_episode_steps`` goes to the env's constructor, not to ``gymnasium.make``'s TimeLimit:
    with the TimeLimit alone the env does not see the limit (gymnasium gives the unwrapped env
    a spec without it) and truncated episodes would miss ``info["episode_metrics"]``.
    """
    import game_env

    cfg = dict(env_config or {})
    spec = gym.spec(game_env.ENV_ID)
    if "max_episode_steps" in cfg:
        spec = dataclasses.replace(
            spec, kwargs={**spec.kwargs, "max_episode_steps": cfg.pop("max_episode_steps")}
        )
    return gym.make(spec, **cfg)


class RaceParallelPettingZooEnv(ParallelPettingZooEnv):
    """RLlib's ParallelPettingZooEnv; `render()` without the mode PettingZoo's signature lacks,
    and the race's map choice forwarded."""

    def render(self) -> Any:
        return self.par_env.render()

    @property
    def map_choice(self) -> Any:
        """The PettingZoo env's map choice (see `game_env` `set_map_choice`)."""
        return self.par_env.map_choice

    def set_map_choice(self, map_id: Any) -> None:
        """Forwarded to the PettingZoo env, so curricula reach it through vector envs."""
        self.par_env.set_map_choice(map_id)


def make_multi_race_env(env_config: Mapping[str, Any] | None = None) -> RaceParallelPettingZooEnv:
    """`game_env.parallel_env(**env_config)` wrapped for RLlib (Tune env creator)."""
    import game_env

    return RaceParallelPettingZooEnv(game_env.parallel_env(**dict(env_config or {})))


RACE_ENVS = {SINGLE_ENV: make_single_race_env, MULTI_ENV: make_multi_race_env}
"""The race's Tune names and their creators (`rllib_asor.registry.envs` reads this table)."""


def register_race_envs() -> None:
    """Register `RACE_ENVS` with Tune (idempotent; call before building)."""
    from ray import tune

    for name, creator in RACE_ENVS.items():
        tune.register_env(name, creator)


# ---------------------------------------------------------------------- metrics
PER_MAP_METRICS = ("success_rate", "goal_reward")
"""Also logged per map as ``race/map_<m>/<name>`` (windowed means), with lifetime totals
``race/map_<m>/episodes|success_sum|goal_reward_sum`` that a map curriculum
(`rllib_asor.race.curriculum`) judges its stages by."""


SLIM_INFO_KEYS = ("reward_terms", "episode_metrics")
"""Per-step info keys of the race that only a racer's last info needs to carry off a runner."""


def slim_infos(agent_episode: Any) -> None:
    """Drop `SLIM_INFO_KEYS` from every info of one single-agent episode (chunk) but its last
    (each slimmed info is a new dict: the dicts themselves may be shared with the runner's
    continuing episode)."""
    data = getattr(getattr(agent_episode, "infos", None), "data", None)
    if not isinstance(data, list):
        return
    for i, info in enumerate(data[:-1]):
        if isinstance(info, Mapping) and any(k in info for k in SLIM_INFO_KEYS):
            data[i] = {k: v for k, v in info.items() if k not in SLIM_INFO_KEYS}


def _last_info(agent_episode: Any) -> Mapping[str, Any] | None:
    """The racer's last info that has ``episode_metrics``, or None."""
    for info in reversed(list(agent_episode.get_infos())):
        if isinstance(info, Mapping) and "episode_metrics" in info:
            return info
    return None


class RaceMetricsCallback(RLlibCallback):
    """Logs ``race/...`` episode metrics and ``race/policy_entropy``.

    On the env runners, each finished racer adds its ``info["episode_metrics"]`` to windowed
    means (`RACE_METRICS`, and `PER_MAP_METRICS` per map); after each iteration they are copied from ``env_runners`` to
    ``result["race"]`` together with the policy entropy (``learners/<policy>/entropy``;
    the mean over policies, and ``race/<policy>/policy_entropy`` when there are several).
    """

    def on_episode_end(
        self,
        *,
        episode: Any,
        prev_episode_chunks: list[Any] | None = None,
        metrics_logger: Any = None,
        **kwargs: Any,
    ) -> None:
        if metrics_logger is None:
            return
        # A racer that finished early may have its last step in an earlier chunk.
        seen: set[Any] = set()
        for chunk in [episode, *reversed(prev_episode_chunks or [])]:
            agent_episodes = getattr(chunk, "agent_episodes", None)
            parts = [(None, chunk)] if agent_episodes is None else list(agent_episodes.items())
            for agent_id, part in parts:
                if agent_id in seen:
                    continue
                info = _last_info(part)
                if info is None:
                    continue
                seen.add(agent_id)
                em = info["episode_metrics"]
                map_key = f"map_{info['map_id']}" if "map_id" in info else None
                for name, key in RACE_METRICS.items():
                    if key not in em:
                        continue
                    value = float(em[key])
                    metrics_logger.log_value(("race", name), value, window=METRICS_WINDOW)
                    if map_key is not None and name in PER_MAP_METRICS:
                        metrics_logger.log_value(
                            ("race", map_key, name), value, window=METRICS_WINDOW
                        )
                if map_key is not None:  # exact running totals (curricula difference them)
                    for name, value in (
                        ("episodes", 1.0),
                        ("success_sum", float(em.get("success", 0.0))),
                        ("goal_reward_sum", float(em.get("goal_reward", 0.0))),
                    ):
                        metrics_logger.log_value(
                            ("race", map_key, name), value, reduce="lifetime_sum"
                        )

    def on_sample_end(self, *, samples: list[Any] | None = None, **kwargs: Any) -> None:
        """The episodes a runner returns keep `SLIM_INFO_KEYS` only in each racer's last info
        (what `_last_info` and the evaluation summaries read); every other step keeps its
        other keys (`dynamics_id`, `map_id`, ...). The Learner reads neither key, and they were
        most of what a runner pickles for the driver (docs/speed.md). Runs after this
        sample's `on_episode_end` calls, on the returned chunks only (the runner's own
        continuing episodes keep theirs)."""
        for chunk in samples or ():
            agent_episodes = getattr(chunk, "agent_episodes", None)
            for part in [chunk] if agent_episodes is None else agent_episodes.values():
                slim_infos(part)

    def on_train_result(self, *, algorithm: Any = None, result: dict, **kwargs: Any) -> None:
        race = dict((result.get("env_runners") or {}).get("race") or {})
        entropies = {
            mid: float(stats["entropy"])
            for mid, stats in (result.get("learners") or {}).items()
            if isinstance(stats, Mapping) and "entropy" in stats
        }
        if entropies:
            race["policy_entropy"] = float(np.mean(list(entropies.values())))
            if len(entropies) > 1:
                for mid, value in entropies.items():
                    race[f"{mid}/policy_entropy"] = value
        if race:
            result.setdefault("race", {}).update(race)


# ---------------------------------------------------------------------- config
def shared_policy_mapping(agent_id: Any, *args: Any, **kwargs: Any) -> str:
    """Every racer acts with the policy `SHARED_POLICY`."""
    return SHARED_POLICY


def race_ppo_config(
    num_racers: int = 1,
    map_id: int | str | None = None,
    *,
    max_episode_steps: int | None = None,
    env_config: Mapping[str, Any] | None = None,
    model_config: Mapping[str, Any] | None = None,
    curriculum: MapCurriculum | Mapping[str, Any] | None = None,
) -> PPOConfig:
    """PPO on the race with `RaceNetModule` and `RaceMetricsCallback` (ASOR not yet wired).

    Args:
        num_racers: 1 → the single-racer gymnasium env; > 1 → the multi-racer env with one
            policy ``"shared"`` for all racers.
        map_id: 0..9, or None / "random" for a random map per episode (the env's rule).
        max_episode_steps: episode length limit (None: the env's default, 1000).
        env_config: further env keyword arguments (``course_seed``, ``frame_skip``,
            ``step_info``: "lean" unless given, ...).
        model_config: `RaceNetModule` settings (see `rllib_asor.race.net.DEFAULTS`).
        curriculum: a `MapCurriculum` (or its dict, as the YAML block) to train over maps
            in stages (`rllib_asor.race.curriculum`); its stages override `map_id`.

    Registers the race envs with Tune. Set training/env-runner settings on the result.
    """
    import game_env

    if not isinstance(num_racers, int) or isinstance(num_racers, bool) or num_racers < 1:
        raise ValueError(f"num_racers={num_racers!r} is invalid: allowed an integer ≥ 1")
    register_race_envs()
    # The per-step reward terms and running metrics are left out (`step_info="lean"`): the
    # callback reads the finished episode's metrics only (docs/speed.md).
    cfg: dict[str, Any] = {"step_info": "lean", **dict(env_config or {}), "map_id": map_id}
    if max_episode_steps is not None:
        cfg["max_episode_steps"] = max_episode_steps
    module_spec = RLModuleSpec(module_class=RaceNetModule, model_config=dict(model_config or {}))
    # Discrete actions: RLlib's unsquash/clip are no-ops on them that still cost ~4 % of the
    # sampling (the CLI's race family sets the same: env_families.RACE.config_defaults).
    config = PPOConfig().callbacks(RaceMetricsCallback)
    # RLlib's PPO Learner with the same-math speed-ups every ASOR Learner has (one nan/inf
    # gradient check per update instead of ~230 host syncs per minibatch, fused Adam, ...):
    # plain PPO and PPO+ASOR then differ only in ASOR (`with_asor` keeps them).
    config.learners(learner_class=LeanPPOTorchLearner)
    config.environment(normalize_actions=False, clip_actions=False)
    if curriculum is not None:
        if not isinstance(curriculum, MapCurriculum):
            curriculum = MapCurriculum.from_dict(curriculum)
        add_callbacks(config, map_curriculum_callback(curriculum))
    if num_racers == 1:
        return config.environment(SINGLE_ENV, env_config=cfg).rl_module(rl_module_spec=module_spec)
    cfg["num_racers"] = num_racers
    policy = PolicySpec(
        observation_space=game_env.observation_space(), action_space=game_env.action_space()
    )
    return (
        config.environment(MULTI_ENV, env_config=cfg)
        .multi_agent(policies={SHARED_POLICY: policy}, policy_mapping_fn=shared_policy_mapping)
        .rl_module(rl_module_spec=MultiRLModuleSpec(rl_module_specs={SHARED_POLICY: module_spec}))
    )
