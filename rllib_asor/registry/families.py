"""What the CLI knows about a family of envs, declared in one place and looked up by env id.

A family names the env ids it covers (by prefix) and its defaults: extra `env_config` for
`--test` runs, the metrics callbacks added when a YAML names none, the RLModule used when a
YAML names none, config keys set when a YAML does not set them, and whether (and how) a
`curriculum:` block is supported. Adding an env family means adding an entry to `FAMILIES`;
the CLI has no env-specific branches.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any


@dataclass(frozen=True)
class EnvFamily:
    """Defaults of the envs whose ids start with one of `prefixes`."""

    name: str
    prefixes: tuple[str, ...]
    test_env_config: Mapping[str, Any] = field(default_factory=dict)
    """Merged into `env_config` by `--test` (e.g. an episode limit, so episodes end in time)."""
    metrics_callbacks: Callable[[], type] | None = None
    """The callbacks class added when the experiment names no `callbacks`."""
    default_module: str | None = None
    """`rl_module.module_class` used when the experiment names none (rllib_asor.registry.models)."""
    config_defaults: Mapping[str, Any] = field(default_factory=dict)
    """Config keys set when the experiment does not set them."""
    env_config_defaults: Mapping[str, Any] = field(default_factory=dict)
    """`env_config` keys set when the experiment does not set them."""
    curriculum: Callable[[Mapping[str, Any]], type] | None = None
    """Builds the callbacks class of a `curriculum:` block (ValueError/TypeError if invalid);
    None: the family has no curriculum."""

    def covers(self, env_id: str) -> bool:
        """Whether `env_id` belongs to this family."""
        return env_id.startswith(self.prefixes)


def _race_metrics() -> type:
    from rllib_asor.race.config import RaceMetricsCallback

    return RaceMetricsCallback


def _race_curriculum(block: Mapping[str, Any]) -> type:
    from rllib_asor.race.curriculum import MapCurriculum, map_curriculum_callback

    return map_curriculum_callback(MapCurriculum.from_dict(dict(block)))


RACE = EnvFamily(
    name="race",
    prefixes=("game_env/",),
    test_env_config={"max_episode_steps": 100},
    metrics_callbacks=_race_metrics,
    default_module="race_net",
    config_defaults={"normalize_actions": False, "clip_actions": False},
    env_config_defaults={"step_info": "lean"},
    curriculum=_race_curriculum,
)
"""The obstacle race (single and multi-racer): race/... metrics, the paper's network, a map
curriculum; `--test` episodes end after 100 steps so race metrics appear in 2 × 256 steps.
Its actions are discrete (MultiDiscrete): RLlib's action unsquash/clip leave them as they are
but deep-copy and walk every sampled action (~4 % of race sampling), so they are off unless the
experiment sets them (`race_ppo_config` uses the same defaults). Its envs leave out the per-step
reward terms and running metrics no Learner or callback reads (`step_info: lean`, the finished
episode's metrics kept; docs/speed.md) unless `env_config` sets it."""

FAMILIES: tuple[EnvFamily, ...] = (RACE,)


def family_of(env_id: str) -> EnvFamily | None:
    """The family covering `env_id`, or None (a plain gymnasium / Tune env)."""
    return next((f for f in FAMILIES if f.covers(env_id)), None)


def families_with_curriculum() -> list[str]:
    """Env id prefixes whose family supports a `curriculum:` block (for error messages)."""
    return [p + "..." for f in FAMILIES if f.curriculum is not None for p in f.prefixes]
