"""Live progress table: iteration, env steps, episode return, and asor/* metrics when present."""

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
MAX_ASOR_COLUMNS = 6


class ProgressReporter(CLIReporter):
    """CLIReporter that adds a column for each `asor/...` metric it sees in the results."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(metric_columns=dict(BASE_COLUMNS), max_report_frequency=10, **kwargs)
        self._asor_seen: set[str] = set()

    def report(self, trials: list[Any], done: bool, *sys_info: str) -> None:
        for trial in trials:
            for key in flatten_dict(trial.last_result or {}, delimiter="/"):
                if len(self._asor_seen) >= MAX_ASOR_COLUMNS:
                    break
                if "asor/" in key and key not in self._asor_seen:
                    self._asor_seen.add(key)
                    self.add_metric_column(key, key[key.index("asor/"):])
        super().report(trials, done, *sys_info)
