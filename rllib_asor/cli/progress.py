"""Live progress of `rllib train`: one line per trial and report, at most 100 columns.

    [0] it 12  steps 123.4k/400k  412/s  ETA 11m  return -12.3  success 0.31  bonus 0.040  disc 0.81

`steps` is `num_env_steps_sampled_lifetime` (over the stop criterion when there is one), ETA
extrapolates the trial's own rate to that criterion (or to `training_iteration`), `success` is
the race's `race/success_rate`, `bonus` is ASOR's `asor/bonus_share` (the amount ASOR adds
to the reward per step, mean |Δr| ÷ the env reward's running RMS) and `disc` its
discriminator accuracy, each shown only when reported (and finite: no `return` before the
first episode ends) and while the line fits. When ASOR looks inert over the last iterations
(`rllib_asor.report.health`), the line ends with why, e.g. `asor inert: disc at chance`.
"""

from __future__ import annotations

import math
import sys
import time
from collections import deque
from collections.abc import Mapping
from typing import Any, TextIO

from ray.tune.progress_reporter import ProgressReporter

from rllib_asor.report.health import WINDOW, health_of_rows

WIDTH = 100
STEPS = "num_env_steps_sampled_lifetime"
ITERATION = "training_iteration"
# (short label, result path, format) of the optional fields, in order.
OPTIONAL = (
    ("return", ("env_runners", "episode_return_mean"), "{:.4g}"),
    ("success", ("race", "success_rate"), "{:.2f}"),
    ("bonus", ("asor", "bonus_share"), "{:.3f}"),
    ("disc", ("asor", "disc_acc"), "{:.2f}"),
    ("stage", ("race", "curriculum_stage"), "{:.0f}"),
)


NO_RETURN = "n/a (no episode finished)"
"""What a summary says for `episode_return_mean` before any episode ended (RLlib reports nan)."""


def finite(value: Any) -> bool:
    """Whether `value` is a number worth showing (not None, nan or inf)."""
    return isinstance(value, int | float) and math.isfinite(value)


class LineReporter(ProgressReporter):
    """Tune progress reporter printing one compact line per trial (see the module docstring)."""

    def __init__(
        self,
        stop: Mapping[str, Any] | None = None,
        every_s: float = 10.0,
        out: TextIO | None = None,
    ) -> None:
        self.stop = dict(stop or {})
        self.every_s = every_s
        self.out = out
        self._last_print = float("-inf")
        self._printed: dict[str, tuple[str, int]] = {}  # trial id -> (status, iteration)
        # trial id -> (iteration, result["asor"]) of the last iterations seen
        self._asor: dict[str, deque[tuple[Any, Any]]] = {}

    def should_report(self, trials: list[Any], done: bool = False) -> bool:
        for t in trials:
            self.observe(t.trial_id, t.last_result or {})
        changed = any(self._new(t) for t in trials)
        return changed and (done or time.monotonic() - self._last_print >= self.every_s)

    def report(self, trials: list[Any], done: bool, *sys_info: str) -> None:
        out = self.out or sys.stdout
        for index, trial in enumerate(trials):
            if not self._new(trial):
                continue
            self._printed[trial.trial_id] = self._key(trial)
            result = trial.last_result or {}
            self.observe(trial.trial_id, result)
            print(self.line(index, trial.status, result, trial.trial_id), file=out, flush=True)
        self._last_print = time.monotonic()

    def observe(self, trial_id: str, result: Mapping[str, Any]) -> None:
        """Keep the ASOR metrics of each new iteration of a trial (for `asor inert: ...`)."""
        asor, it = result.get("asor"), result.get(ITERATION)
        if not isinstance(asor, Mapping) or it is None:
            return
        seen = self._asor.setdefault(trial_id, deque(maxlen=WINDOW))
        if not seen or seen[-1][0] != it:
            seen.append((it, asor))

    def line(
        self, index: int, status: str, result: Mapping[str, Any], trial_id: str | None = None
    ) -> str:
        """The progress line of one trial's latest result (with `trial_id`: and whether its
        ASOR looks inert over the iterations `observe` kept)."""
        it = result.get(ITERATION)
        if it is None:
            return f"[{index}] {status.lower()}"
        parts = [f"[{index}] it {it}"]
        steps, elapsed = result.get(STEPS), result.get("time_total_s")
        if steps is not None:
            goal = self.stop.get(STEPS)
            parts.append(f"steps {_si(steps)}" + (f"/{_si(goal)}" if goal else ""))
            if elapsed:
                parts.append(f"{steps / elapsed:.0f}/s")
        eta = self._eta(result)
        if eta is not None and status == "RUNNING":
            parts.append(f"ETA {_duration(eta)}")
        tail = [] if status in ("RUNNING", "PENDING") else [status.lower()]
        history = self._asor.get(trial_id, ()) if trial_id is not None else ()
        inert = health_of_rows([{"asor": asor} for _, asor in history])
        if inert is not None:
            tail.insert(0, inert.short)
        for label, path, fmt in OPTIONAL:  # in order, as many as fit
            value = _get(result, path)
            part = f"{label} {fmt.format(value)}" if finite(value) else None
            if part and len("  ".join([*parts, part, *tail])) <= WIDTH:
                parts.append(part)
        return "  ".join([*parts, *tail])[:WIDTH]

    def _eta(self, result: Mapping[str, Any]) -> float | None:
        elapsed = result.get("time_total_s")
        for key in (STEPS, ITERATION):
            goal, done = self.stop.get(key), result.get(key)
            if goal and done and elapsed:
                return max(0.0, elapsed * (float(goal) - done) / done)
        return None

    def _new(self, trial: Any) -> bool:
        """Whether `trial` has something to show: a new result or a new state (not PENDING)."""
        return trial.status != "PENDING" and self._key(trial) != self._printed.get(trial.trial_id)

    @staticmethod
    def _key(trial: Any) -> tuple[str, int]:
        return trial.status, (trial.last_result or {}).get(ITERATION, 0)


def _get(result: Mapping[str, Any], path: tuple[str, ...]) -> Any:
    value: Any = result
    for part in path:
        if not isinstance(value, Mapping):
            return None
        value = value.get(part)
    return value


def _si(n: float) -> str:
    n = float(n)
    for unit, size in (("M", 1e6), ("k", 1e3)):
        if abs(n) >= size:
            return f"{n / size:.4g}{unit}"
    return f"{n:.0f}"


def _duration(seconds: float) -> str:
    seconds = int(seconds)
    if seconds >= 3600:
        return f"{seconds // 3600}h{seconds % 3600 // 60:02d}m"
    if seconds >= 600:
        return f"{seconds // 60}m"
    if seconds >= 60:
        return f"{seconds // 60}m{seconds % 60:02d}s"
    return f"{seconds}s"
