"""RLlib's timers per training iteration, for `benchmarks.scaling --parts split`.

RLlib 2.60 logs its timers (`timers/...`, the env runners' and the Learner's connector timers)
with `reduce="ema"` and a coefficient of 0.01 that is never reset: a result row's timer is an
average over the whole run, dominated by the first (warm-up) iterations, not the time of that
iteration. `ITERATION_STATS` maps "ema" to `IterationMeanStats`, the mean of the values logged
since the last reduce (one value per iteration for the Algorithm's timers and the Learner's
connector pipeline; the per-step mean for per-step timers), so each result row carries that
iteration's times. Set it on both arms of a comparison:
`config.reporting(custom_stats_cls_lookup=ITERATION_STATS)`; it changes only what is reported.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from ray.rllib.utils.metrics.metrics_logger import DEFAULT_STATS_CLS_LOOKUP
from ray.rllib.utils.metrics.stats.ema import EmaStats
from ray.rllib.utils.metrics.stats.utils import safe_isnan


class IterationMeanStats(EmaStats):
    """RLlib's `EmaStats` whose leaf reports the mean of the values pushed since its last
    reduce, then starts over (merging above the leaves is EmaStats' own: the mean of the
    incoming values, e.g. over env runners)."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._sum: Any = 0.0
        self._count = 0

    def push(self, value: Any) -> None:
        if safe_isnan(value):
            return
        if hasattr(value, "detach"):  # a torch tensor stays where it is (no host sync)
            value = value.detach()
        self._sum = self._sum + value
        self._count += 1
        self._value = self._sum / self._count

    def reduce(self, compile: bool = True) -> Any:
        out = super().reduce(compile)
        if self.is_leaf:
            self._sum, self._count, self._value = 0.0, 0, np.nan
        return out


ITERATION_STATS = {**DEFAULT_STATS_CLS_LOOKUP, "ema": IterationMeanStats}
"""RLlib's stats classes with "ema" per iteration (see the module docstring)."""
