"""A paired comparison of two methods over seeds: the numbers `rllib compare` prints.

Seed ``s`` of both methods shares the env seeds (and, where the algorithm allows, the initial
weights), so the difference ``d_s = treatment_s - baseline_s`` cancels the seed's luck:

- interval: 95 % BCa bootstrap of mean(d) (`rllib_asor.report.stats.bootstrap_ci`: scipy,
  5,000 resamples, fixed seed);
- p-value: Wilcoxon signed-rank test of d (`scipy.stats.wilcoxon`, two-sided unless asked);
- probability of improvement P(treatment > baseline) and the IQM of each method
  (`rliable.metrics`, Agarwal et al. 2021), over the paired runs;
- pairs needed for the observed effect at 80 % power, two-sided 5 %:
  n ≈ ((z₀.₉₇₅ + z₀.₈) · sd(d) / mean(d))²;
- per ``dynamics_id``: the p-values of one comparison's dynamics adjusted together (`holm`,
  Holm–Bonferroni); a row is decided (`decided`, the one rule the table and the figure use) only
  when its adjusted p < 5 % and its interval excludes 0, else it is exploratory.

The studies' tables (studies/lib) take their numbers from here too: `unpaired_difference` (every
run, seeds pooled: percentile bootstrap of the difference of means and a one-sided Mann–Whitney
U) and `other_intervals` (the paired percentile bootstrap, the paired t-interval and the
unpaired interval, to show that a verdict does not hang on the choice of interval).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

from rllib_asor.report.stats import BOOTSTRAP_RESAMPLES, bootstrap_ci

CI_METHOD = (
    f"95% BCa bootstrap interval of the mean paired difference ({BOOTSTRAP_RESAMPLES:,} resamples)"
)
TEST_NAME = "Wilcoxon signed-rank"
POWER = 0.8
ALPHA = 0.05


@dataclass
class Paired:
    """One comparison: treatment against baseline, paired by seed."""

    baseline: str
    treatment: str
    metric: str
    pairs: int
    seeds: list[Any]
    baseline_mean: float
    treatment_mean: float
    diff_mean: float
    diff_std: float
    ci_low: float
    ci_high: float
    p_value: float
    test: str
    prob_improvement: float
    baseline_iqm: float
    treatment_iqm: float
    pairs_needed: int | None
    verdict: str
    env: str = ""
    dynamics: str | None = None
    differs_in: list[str] = field(default_factory=list)
    arms: str = ""
    """`differs_in` in words, as `rllib ab` says it (`rllib_asor.report.grouping.arm_account`)."""
    diffs: list[float] = field(default_factory=list)
    asor_health: str | None = None
    """One line when the treatment's ASOR looks inert (`rllib_asor.report.health`)."""
    withheld: str | None = None
    """Why no verdict is given (smoke run, an arm never trained, ASOR never ran), else None."""
    smoke: bool = False
    """The trials are smoke runs (`rllib_asor.report.results.SMOKE_KEY`)."""
    p_adjusted: float = math.nan
    """Per dynamics: the Holm-adjusted p over the comparison's dynamics (NaN for the overall row)."""
    dynamics_compared: int = 0
    """Per dynamics: how many dynamics the adjustment covered."""
    baseline_episodes: int | None = None
    treatment_episodes: int | None = None
    """Per dynamics: evaluation episodes behind the paired scores, summed over the trials."""
    baseline_min_episodes: int | None = None
    treatment_min_episodes: int | None = None
    """Per dynamics: the fewest episodes behind one trial's score."""
    dynamics_one_arm: dict[str, list[str]] = field(default_factory=dict)
    """Overall row: per group, the dynamics only its evaluation has (the other arm has none)."""
    dynamics_training_only: list[str] = field(default_factory=list)
    """Overall row: dynamics seen in training but in no evaluation episode."""

    @property
    def few_episodes(self) -> bool:
        """Per dynamics: some trial's score rests on fewer than `MIN_EPISODES` episodes."""
        counts = [
            c for c in (self.baseline_min_episodes, self.treatment_min_episodes) if c is not None
        ]
        return bool(counts) and min(counts) < MIN_EPISODES

    def to_json(self) -> dict[str, Any]:
        """A JSON-able dict (NaN -> None), with `decided` and `few_episodes`."""
        out = {
            k: (None if isinstance(v, float) and not math.isfinite(v) else v)
            for k, v in asdict(self).items()
        }
        out["decided"] = decided(self)
        out["few_episodes"] = self.few_episodes
        return out


MIN_EPISODES = 2
"""A per-dynamics row whose trials have fewer evaluation episodes than this is flagged ``few``."""


def decided(r: Paired) -> bool:
    """Whether `r` decides: no reason to withhold a verdict, the 95 % interval excludes 0, and
    p < 5 % (per dynamics: the Holm-adjusted p). The table, the verdict and the figure ask this."""
    if r.withheld is not None or r.pairs < 2:
        return False
    p = r.p_adjusted if r.dynamics is not None else r.p_value
    return bool(p < ALPHA) and (r.ci_low > 0 or r.ci_high < 0)


def holm(p_values: Sequence[float]) -> list[float]:
    """Holm–Bonferroni adjusted p-values, in the given order; NaNs stay NaN and do not count."""
    idx = sorted((i for i, p in enumerate(p_values) if math.isfinite(p)), key=lambda i: p_values[i])
    out = [math.nan] * len(p_values)
    running = 0.0
    for rank, i in enumerate(idx):
        running = max(running, min(1.0, (len(idx) - rank) * p_values[i]))
        out[i] = running
    return out


def adjust_dynamics(rows: Sequence[Paired]) -> None:
    """Holm-adjust the per-dynamics rows of one comparison together and set their verdicts."""
    adjusted = holm([r.p_value for r in rows])
    for r, p in zip(rows, adjusted, strict=True):
        r.p_adjusted, r.dynamics_compared = p, len(rows)
        if r.withheld is not None:
            continue
        if decided(r):
            side = "better" if r.ci_low > 0 else "worse"
            r.verdict = (
                f"treatment {side}: the 95% interval excludes 0 and the Holm-adjusted p < "
                f"{ALPHA:g} (over {len(rows)} dynamics)"
            )
        else:  # "no difference observed" and "one pair" still hold; a raw decision does not
            kept = "" if r.verdict.startswith(("treatment", "too wide")) else f"; {r.verdict}"
            r.verdict = f"exploratory: Holm-adjusted p {p:.3g} over {len(rows)} dynamics{kept}"
        r.pairs_needed = None


def pairs_needed(diff_mean: float, diff_std: float) -> int | None:
    """Pairs for 80 % power at two-sided 5 % to detect `diff_mean` (None if undefined)."""
    from scipy.stats import norm

    if (
        not (math.isfinite(diff_mean) and math.isfinite(diff_std))
        or diff_mean == 0
        or diff_std == 0
    ):
        return None
    z = norm.ppf(1 - ALPHA / 2) + norm.ppf(POWER)
    return math.ceil((z * diff_std / abs(diff_mean)) ** 2)


MIN_PAIRS = next(n for n in range(1, 64) if 2 / 2**n < ALPHA)
"""Fewest pairs with which the two-sided signed-rank test can reach p < 5 % (2/2ⁿ): 6."""


def _verdict(p: Paired) -> tuple[str, int | None]:
    """Decided only when the interval excludes 0 **and** the test agrees (p < 5 %): with few
    pairs a bootstrap interval can exclude 0 while no test could (2 pairs: p ≥ 0.5)."""
    if p.pairs < 2:
        return "one pair: no interval; run more seeds", None
    if decided(p):
        side = "better" if p.ci_low > 0 else "worse"
        return f"treatment {side}: the 95% interval excludes 0 and p < {ALPHA:g}", None
    need = pairs_needed(p.diff_mean, p.diff_std)
    if need is None:
        return "no difference observed", None
    need = max(need, p.pairs + 1, MIN_PAIRS)
    return (
        f"too wide to decide — about {need} pairs needed for the observed effect "
        f"({p.diff_mean:+.4g}; {POWER:.0%} power, two-sided {ALPHA:.0%})",
        need,
    )


def paired_difference(
    baseline: Mapping[Any, float],
    treatment: Mapping[Any, float],
    *,
    baseline_name: str = "baseline",
    treatment_name: str = "treatment",
    metric: str = "",
    alternative: str = "two-sided",
) -> Paired:
    """Compare two methods' scores per seed, over the seeds both have (finite scores only).

    ValueError when no seed has a finite score in both.
    """
    from rliable.metrics import aggregate_iqm, probability_of_improvement
    from scipy.stats import wilcoxon

    seeds = sorted(
        (s for s in baseline.keys() & treatment.keys()
         if math.isfinite(baseline[s]) and math.isfinite(treatment[s])),
        key=lambda s: (str(type(s)), s),
    )  # fmt: skip
    if not seeds:
        raise ValueError(f"{treatment_name} and {baseline_name} have no seed in common")
    x = np.array([baseline[s] for s in seeds], dtype=float)
    y = np.array([treatment[s] for s in seeds], dtype=float)
    d = y - x
    lo, hi = bootstrap_ci(d)
    if np.any(d != 0):
        p = float(wilcoxon(d, alternative=alternative).pvalue)
    else:
        p = 1.0
    result = Paired(
        baseline=baseline_name,
        treatment=treatment_name,
        metric=metric,
        pairs=len(seeds),
        seeds=seeds,
        baseline_mean=float(x.mean()),
        treatment_mean=float(y.mean()),
        diff_mean=float(d.mean()),
        diff_std=float(d.std(ddof=1)) if len(d) > 1 else math.nan,
        ci_low=lo,
        ci_high=hi,
        p_value=p,
        test=f"{TEST_NAME}, {alternative}",
        prob_improvement=float(probability_of_improvement(y[:, None], x[:, None])),
        baseline_iqm=float(aggregate_iqm(x[:, None])),
        treatment_iqm=float(aggregate_iqm(y[:, None])),
        pairs_needed=None,
        verdict="",
        diffs=[float(v) for v in d],
    )
    result.verdict, result.pairs_needed = _verdict(result)
    return result


def _std(x: np.ndarray) -> float:
    return float(x.std(ddof=1)) if len(x) > 1 else 0.0


def unpaired_difference(
    baseline: Sequence[float],
    treatment: Sequence[float],
    *,
    n_resamples: int = 9999,
    seed: int = 0,
) -> dict[str, float]:
    """Every run, seeds pooled: mean/std of both samples, diff = mean(treatment) −
    mean(baseline), its 95% percentile bootstrap interval (`ci_low`, `ci_high`; both samples
    resampled independently) and the one-sided Mann–Whitney U p-value for treatment > baseline.

    A constant sample (n = 1 included) has a degenerate bootstrap distribution, so only the
    other one is resampled; two constant samples give [diff, diff]; all values tied gives p = 1.
    ValueError when a sample is empty.
    """
    from scipy.stats import bootstrap, mannwhitneyu

    x, y = np.asarray(baseline, dtype=float), np.asarray(treatment, dtype=float)
    if len(x) == 0 or len(y) == 0:
        raise ValueError("an unpaired comparison needs at least one value in each sample")
    diff = float(y.mean() - x.mean())
    const_x, const_y = bool(np.all(x == x[0])), bool(np.all(y == y[0]))
    if const_x and const_y:
        lo = hi = diff
    else:
        if const_x or const_y:  # resample the varying sample only, shifted by the constant
            data, sign, shift = ((y,), 1.0, -x[0]) if const_x else ((x,), -1.0, y[0])

            def stat(*s: np.ndarray, axis: int = -1) -> np.ndarray:
                return shift + sign * s[0].mean(axis=axis)
        else:
            data = (x, y)

            def stat(*s: np.ndarray, axis: int = -1) -> np.ndarray:
                return s[1].mean(axis=axis) - s[0].mean(axis=axis)

        res = bootstrap(
            data, stat, vectorized=True, paired=False, method="percentile",
            n_resamples=n_resamples, rng=np.random.default_rng(seed),
        )  # fmt: skip
        lo, hi = float(res.confidence_interval.low), float(res.confidence_interval.high)
    if np.all(np.concatenate([x, y]) == x[0]):
        p = 1.0
    else:
        p = float(mannwhitneyu(y, x, alternative="greater").pvalue)
    return {
        "n_baseline": len(x),
        "mean_baseline": float(x.mean()),
        "std_baseline": _std(x),
        "n_treatment": len(y),
        "mean_treatment": float(y.mean()),
        "std_treatment": _std(y),
        "diff": diff,
        "ci_low": lo,
        "ci_high": hi,
        "p_value": p,
    }


def other_intervals(
    baseline: Mapping[Any, float], treatment: Mapping[Any, float]
) -> dict[str, tuple[float, float]]:
    """95 % intervals of (treatment − baseline) other than the BCa one `paired_difference`
    decides by: ``paired_percentile`` (bootstrap of the per-seed differences, seeded),
    ``paired_t`` (t-interval of their mean) and ``unpaired`` (`unpaired_difference`, every run)."""
    from scipy import stats

    seeds = sorted(set(baseline) & set(treatment), key=str)
    d = np.array([treatment[s] - baseline[s] for s in seeds])
    pct = stats.bootstrap(
        (d,), np.mean, method="percentile", rng=np.random.default_rng(0)
    ).confidence_interval
    t = stats.t.interval(0.95, len(d) - 1, loc=d.mean(), scale=stats.sem(d))
    c = unpaired_difference(list(baseline.values()), list(treatment.values()))
    return {
        "paired_percentile": (float(pct.low), float(pct.high)),
        "paired_t": (float(t[0]), float(t[1])),
        "unpaired": (c["ci_low"], c["ci_high"]),
    }
