"""Live progress table: iteration, env steps, episode return, asor/* (race/*) metrics when present."""

from __future__ import annotations

from typing import Any

from ray.tune import CLIReporter
from ray.tune.utils import flatten_dict

BASE_COLUMNS = {
    "training_iteration": "iter",
    "num_env_steps_sampled_lifetime": "env steps",
    "env_runners/episode_return_mean": "return mean",
    "time_total_s": "time (s)",
}
MAX_ASOR_COLUMNS = 8
# Race metrics (result["race"], RaceMetricsCallback) shown when present.
RACE_COLUMNS = ("success_rate", "trapped_rate", "curriculum_stage")
# Shown first when present (DESIGN.md names); other asor/* metrics fill the remaining columns.
PREFERRED_ASOR = ("disc_acc", "real_fraction", "aug_reward_mean", "disc_loss", "rnd_loss", "lambda")


class ProgressReporter(CLIReporter):
    """CLIReporter that adds columns for the `asor/...` (and `race/...`) metrics it sees."""

    def __init__(self, **kwargs: Any) -> None:
        # print_intermediate_tables defaults to "Tune's global verbosity >= 3 at construction",
        # which a previous run in the same process lowers: ask for the table explicitly.
        super().__init__(
            metric_columns=dict(BASE_COLUMNS),
            max_report_frequency=10,
            print_intermediate_tables=True,
            **kwargs,
        )
        self._asor_seen: set[str] = set()

    def report(self, trials: list[Any], done: bool, *sys_info: str) -> None:
        found: set[str] = set()
        for trial in trials:
            result = {k: v for k, v in (trial.last_result or {}).items() if k != "config"}
            found.update(
                k
                for k in flatten_dict(result, delimiter="/")
                if k.startswith("asor/") or "/asor/" in k
            )
            race = result.get("race") or {}
            found.update(f"race/{k}" for k in RACE_COLUMNS if k in race)
        for key in sorted(found - self._asor_seen, key=_rank):
            if len(self._asor_seen) >= MAX_ASOR_COLUMNS:
                break
            self._asor_seen.add(key)
            self.add_metric_column(key, key[key.index("asor/") :] if "asor/" in key else key)
        super().report(trials, done, *sys_info)


def _rank(key: str) -> tuple[int, str]:
    if key.startswith("race/"):
        return (-1, key)
    name = key.rsplit("asor/", 1)[-1]
    return (PREFERRED_ASOR.index(name) if name in PREFERRED_ASOR else len(PREFERRED_ASOR), key)
