"""Is ASOR doing anything? One diagnosis from the `asor/...` metrics of the last iterations,
shared by the progress line of `rllib train`, `rllib report` and `rllib compare`.

ASOR is *inert* when, in each of the last `WINDOW` iterations (fewer: no verdict yet),

- `active` is 0: the bonus is off, because the archive holds no states (`archive_states` 0:
  no episode has ended) or the critic never became ready (`critic_ev` ≤ 0: the warm-up waits
  for an explained variance above 0);
- the discriminator is at chance: its Jensen–Shannon estimate `js_estimate` < `CHANCE_JS`
  (its loss within 0.01 of log 2), so ω ≈ ½ everywhere and the bonus carries no information;
- or the bonus is near zero: `bonus_share` (mean |Δr| ÷ the env reward's running RMS, the
  amount ASOR adds per step) < `TINY_BONUS`.

The thresholds sit well below what working runs log (docs/results.md: JS 0.38–0.51 for a sharp
discriminator, 0.03–0.06 for the robust preset's gentle one; `bonus_share` 0.005–0.03 with the
default batch normalisation), and above the inert run they were set from (JS ≈ 0.003, critic
explained variance 0.0007).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

WINDOW = 10
"""Iterations in a row that must all look inert."""
CHANCE_JS = 0.01
"""`js_estimate` below this (of log 2 ≈ 0.69) is a discriminator at chance."""
LOW_EV = 0.05
"""A critic whose explained variance stays below this splits states by value almost at random."""
TINY_BONUS = 0.001
"""`bonus_share` below this (0.1 % of the reward's scale) is a bonus near zero."""
PREFIX = "asor/"


@dataclass(frozen=True)
class Inert:
    """Why ASOR looks inert and what to try."""

    short: str
    """For the progress line, e.g. ``asor inert: disc at chance``."""
    cause: str
    advice: str

    @property
    def line(self) -> str:
        """The one line `rllib report` and `rllib compare` print."""
        return f"{self.short} ({self.cause}); try: {self.advice}"


def _values(history: Sequence[Mapping[str, Any]], key: str) -> list[float] | None:
    """The finite values of `key` in every row, or None when a row lacks it."""
    out = []
    for row in history:
        v = row.get(key)
        if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
            return None
        out.append(float(v))
    return out


def asor_health(history: Sequence[Mapping[str, Any]], window: int = WINDOW) -> Inert | None:
    """The diagnosis of one policy's ASOR from its per-iteration metrics (oldest first, flat
    names: ``js_estimate``, ``active``, ...); None while it looks alive or has fewer than
    `window` iterations with ASOR metrics."""
    rows = [r for r in history if r][-window:]
    if len(rows) < window:
        return None
    n = len(rows)
    active = _values(rows, "active")
    ev = _values(rows, "critic_ev")
    if active is not None and max(active) == 0.0:
        archive = _values(rows, "archive_states")
        if archive is not None and max(archive) == 0.0:
            return Inert(
                "asor inert: archive empty",
                f"no episode ended in the last {n} iterations, so there are no real states "
                "and the bonus stays off",
                "episodes that end within a train batch (a time limit), or real_source: batch",
            )
        if ev is not None and max(ev) <= 0.0:
            return Inert(
                "asor inert: critic not ready",
                f"the critic's explained variance stayed ≤ 0 (last {ev[-1]:.3g}) for {n} "
                "iterations; the bonus waits for it",
                "check the critic's explained variance (its lr, vf_loss_coeff, vf_clip_param), "
                "or lambda_warmup: false",
            )
        return Inert(
            "asor inert: bonus off",
            f"`asor/active` was 0 for {n} iterations (no real states in the batches)",
            "check `asor/real_fraction` and the partition (rho_value, rho_count)",
        )
    js = _values(rows, "js_estimate")
    if js is not None and max(js) < CHANCE_JS:
        weak = ev is not None and max(ev) < LOW_EV
        cause = (
            f"discriminator JS estimate below {CHANCE_JS:g} for {n} iterations (last {js[-1]:.2g})"
        )
        if weak:
            cause += (
                f"; the critic's explained variance is {ev[-1]:.2g}, so the split by value is "
                "near random"
            )
        advice = (
            "check the critic's explained variance, a longer warm-up (a lambda_ schedule "
            "that starts later), or observation keys that tell good states apart (obs_keys)"
        )
        return Inert("asor inert: disc at chance", cause, advice)
    share = _values(rows, "bonus_share")
    if share is not None and max(share) < TINY_BONUS:
        return Inert(
            "asor inert: bonus ~0",
            f"the bonus was below {TINY_BONUS:.1%} of the reward's scale for {n} iterations "
            f"(last {share[-1]:.2g})",
            "raise lambda_ (e.g. ×10), or bonus_share_max if the share is capped",
        )
    return None


def policy_histories(
    rows: Iterable[Mapping[str, Any]], prefix: str = PREFIX
) -> dict[str, list[dict[str, Any]]]:
    """Per policy ("" for one policy), the ASOR metrics of each row: flattened result rows
    (``asor/js_estimate`` or ``asor/<policy>/js_estimate``) or nested ones (``{"asor": ...}``)."""
    out: dict[str, list[dict[str, Any]]] = {}
    for row in rows:
        per: dict[str, dict[str, Any]] = {}
        nested = row.get(prefix.rstrip("/"))
        if isinstance(nested, Mapping):
            for k, v in nested.items():
                if isinstance(v, Mapping):
                    per.setdefault(str(k), {}).update(v)
                else:
                    per.setdefault("", {})[k] = v
        for key, v in row.items():
            if not key.startswith(prefix):
                continue
            parts = key[len(prefix) :].split("/")
            if len(parts) == 1:
                per.setdefault("", {})[parts[0]] = v
            elif len(parts) == 2:
                per.setdefault(parts[0], {})[parts[1]] = v
        for pid, metrics in per.items():
            out.setdefault(pid, []).append(metrics)
    return out


def health_of_rows(rows: Iterable[Mapping[str, Any]]) -> Inert | None:
    """The first inert policy's diagnosis (its id prefixed when there are several)."""
    for pid, history in sorted(policy_histories(rows).items()):
        found = asor_health(history)
        if found is not None:
            if pid:
                return Inert(found.short.replace("asor inert", f"asor inert ({pid})", 1),
                             found.cause, found.advice)  # fmt: skip
            return found
    return None


def group_health(label: str, trial_rows: Sequence[Sequence[Mapping[str, Any]]]) -> str | None:
    """One line for a group of trials: the most common diagnosis and in how many trials."""
    found = [h for h in (health_of_rows(rows) for rows in trial_rows) if h is not None]
    if not found:
        return None
    counts: dict[str, int] = {}
    for h in found:
        counts[h.short] = counts.get(h.short, 0) + 1
    top = max(counts, key=lambda s: counts[s])
    first = next(h for h in found if h.short == top)
    return f"{label}: {top} in {counts[top]}/{len(trial_rows)} trial(s) ({first.cause}); try: {first.advice}"
