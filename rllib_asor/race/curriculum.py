"""A curriculum over the race's maps: train on easy maps first, widen when they are solved.

    curriculum = MapCurriculum(stages=[[2], [2, 0, 4], "random"], threshold=0.5)
    config.callbacks([RaceMetricsCallback, map_curriculum_callback(curriculum)])

or, in a YAML file for a ``game_env/*`` env, a ``curriculum:`` block in ``config`` (the CLI
does the above)::

    config:
      curriculum: {stages: [[2], [2, 0, 4], random], metric: success_rate, threshold: 0.5}

Each stage is a map choice as the env's ``map_id`` takes it (an int, a list of ints, or
``random`` for all ten). After every training iteration the callback averages the per-map
training metric over the stage's maps, each map's value taken over its latest
``min_episodes`` finished racer-episodes in this stage (exact, from `RaceMetricsCallback`'s
lifetime totals ``race/map_<m>/episodes|success_sum|goal_reward_sum``); when that mean reaches
``threshold``, the next stage's maps are pushed to every env (``set_map_choice``, effective at each env's next reset).
``max_env_steps`` (optional) moves on after that many env steps in a stage regardless.
The stage and its score are logged as ``race/curriculum_stage`` and ``race/curriculum_score``
(the score only once every map of the stage has enough episodes).

The stage lives on the driver; env runners that are recreated after a failure get it again
(`on_env_runners_recreated`). A run restored from a checkpoint starts at stage 0 again and
moves through the stages it has solved as soon as their episodes come in.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

from ray.rllib.callbacks.callbacks import RLlibCallback

from game_env.maps import NUM_MAPS
from game_env.options import MapChoice, check_map_choice

METRICS = ("success_rate", "goal_reward")
"""Per-map training metrics a stage can be judged by (``race/map_<m>/<metric>``)."""


def _check_count(name: str, value: Any, alternative: str = "") -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(
            f"curriculum {name}={value!r} is not valid; allowed: an int >= 1{alternative}"
        )


@dataclasses.dataclass(frozen=True)
class MapCurriculum:
    """Stages of map choices and the rule that moves from one to the next (module docstring)."""

    stages: tuple[MapChoice, ...]
    metric: str = "success_rate"
    threshold: float = 0.5
    min_episodes: int = 20
    max_env_steps: int | None = None

    def __post_init__(self) -> None:
        if isinstance(self.stages, str | bytes) or not isinstance(self.stages, Sequence):
            raise ValueError(
                f"curriculum stages={self.stages!r} is not valid; allowed: a non-empty list of "
                "map choices (an int 0..9, a list of them, or 'random')"
            )
        if not self.stages:
            raise ValueError("curriculum stages=[] is empty; allowed: at least one stage")
        stages = []
        for i, stage in enumerate(self.stages):
            try:
                stages.append(check_map_choice(stage))
            except ValueError as e:
                raise ValueError(f"curriculum stage {i}: {e}") from None
        object.__setattr__(self, "stages", tuple(stages))
        if self.metric not in METRICS:
            raise ValueError(
                f"curriculum metric={self.metric!r} is not supported; allowed: {list(METRICS)}"
            )
        if isinstance(self.threshold, bool) or not isinstance(self.threshold, int | float):
            raise ValueError(
                f"curriculum threshold={self.threshold!r} is not valid; allowed: a number"
            )
        if self.metric == "success_rate" and not 0.0 < self.threshold <= 1.0:
            raise ValueError(
                f"curriculum threshold={self.threshold!r} is out of range for success_rate; "
                "allowed: 0 < threshold <= 1"
            )
        _check_count("min_episodes", self.min_episodes)
        if self.max_env_steps is not None:
            _check_count("max_env_steps", self.max_env_steps, " or null")

    @classmethod
    def from_dict(cls, block: Mapping[str, Any]) -> MapCurriculum:
        """From a YAML ``curriculum:`` block; unknown keys raise ValueError naming the allowed."""
        if not isinstance(block, Mapping):
            raise ValueError(f"curriculum={block!r} is not valid; allowed: a mapping with 'stages'")
        fields = [f.name for f in dataclasses.fields(cls)]
        unknown = sorted(set(block) - set(fields))
        if unknown:
            raise ValueError(f"curriculum: unknown key(s) {unknown}; allowed: {fields}")
        if "stages" not in block:
            raise ValueError("curriculum: 'stages' is missing (a list of map choices)")
        return cls(**dict(block))

    def maps(self, stage: int) -> list[int]:
        """The map ids stage `stage` draws from."""
        choice = self.stages[stage]
        if choice is None:
            return list(range(NUM_MAPS))
        return [choice] if isinstance(choice, int) else list(choice)


def set_maps(env_runner: Any, choice: MapChoice) -> None:
    """Set the map choice on every race env of one env runner (single- or multi-racer)."""
    env = getattr(env_runner, "env", None)
    if env is None:  # e.g. the local env runner when remote ones sample
        return
    base = getattr(env, "unwrapped", env)
    if hasattr(base, "num_envs") and hasattr(base, "call"):  # a gymnasium vector env
        base.call("set_map_choice", choice)
        return
    base.set_map_choice(choice)  # a race env (RaceParallelPettingZooEnv forwards it)


def map_curriculum_callback(curriculum: MapCurriculum) -> type[RLlibCallback]:
    """An RLlib callback class running `curriculum` (add it next to `RaceMetricsCallback`)."""
    return type("MapCurriculumCallback", (MapCurriculumCallback,), {"curriculum": curriculum})


_SUMS = {"success_rate": "success_sum", "goal_reward": "goal_reward_sum"}


class MapCurriculumCallback(RLlibCallback):
    """Runs the class attribute `curriculum`; make subclasses with `map_curriculum_callback`."""

    curriculum: MapCurriculum

    def __init__(self) -> None:
        super().__init__()
        self.stage = 0
        self._stage_start_steps = 0
        # Per map: (episodes, metric sum) lifetime totals after each iteration of this stage.
        self._history: dict[int, list[tuple[float, float]]] = {}

    def _push(self, algorithm: Any) -> None:
        choice = self.curriculum.stages[self.stage]
        algorithm.env_runner_group.foreach_env_runner(lambda er: set_maps(er, choice))

    def on_algorithm_init(self, *, algorithm: Any, **kwargs: Any) -> None:
        self._push(algorithm)

    def on_env_runners_recreated(
        self, *, algorithm: Any, is_evaluation: bool = False, **kwargs: Any
    ) -> None:
        if not is_evaluation:
            self._push(algorithm)

    def _recent(self, m: int) -> float | None:
        """Metric mean over map `m`'s most recent >= min_episodes episodes of this stage."""
        history = self._history.get(m) or []
        if not history:
            return None
        episodes, total = history[-1]
        for then_episodes, then_total in reversed(history[:-1]):
            if episodes - then_episodes >= self.curriculum.min_episodes:
                return (total - then_total) / (episodes - then_episodes)
        return None

    def on_train_result(self, *, algorithm: Any = None, result: dict, **kwargs: Any) -> None:
        race = (result.get("env_runners") or {}).get("race") or {}
        steps = int(result.get("num_env_steps_sampled_lifetime", 0))
        maps = self.curriculum.maps(self.stage)
        for m in maps:
            stats = race.get(f"map_{m}") or {}
            point = (
                float(stats.get("episodes", 0.0)),
                float(stats.get(_SUMS[self.curriculum.metric], 0.0)),
            )
            history = self._history.setdefault(m, [point])
            if point != history[-1]:
                history.append(point)
        recent = [self._recent(m) for m in maps]
        ready = all(v is not None for v in recent)
        score = sum(recent) / len(recent) if ready else float("nan")  # type: ignore[arg-type]
        last = self.stage == len(self.curriculum.stages) - 1
        cap = self.curriculum.max_env_steps
        timed_out = cap is not None and steps - self._stage_start_steps >= cap
        if not last and ((ready and score >= self.curriculum.threshold) or timed_out):
            self.stage += 1
            self._stage_start_steps = steps
            self._history = {}  # the next stage is judged on its own episodes
            self._push(algorithm)
        result.setdefault("race", {})
        result["race"]["curriculum_stage"] = self.stage
        if ready:  # before every map has enough episodes: absent, never NaN
            result["race"]["curriculum_score"] = score
