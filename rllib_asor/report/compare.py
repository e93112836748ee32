"""`rllib compare`: every treatment group against the baseline, paired by seed, per env and per
``dynamics_id``. Reading is `results`, grouping `grouping`, the score `scores`, statistics
`paired`; this module puts them together and renders the text."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field

from rllib_asor.report.grouping import (
    Group,
    arm_account,
    differing_settings,
    group_trials,
    trial_seed,
)
from rllib_asor.report.health import group_health
from rllib_asor.report.paired import (
    ALPHA,
    CI_METHOD,
    MIN_EPISODES,
    Paired,
    adjust_dynamics,
    decided,
    paired_difference,
)
from rllib_asor.report.readiness import withheld
from rllib_asor.report.results import SMOKE_LABEL, Trial, asor_mode, find_trials, is_smoke
from rllib_asor.report.scores import (
    EVALUATIONS,
    TRAIN_KEY,
    Source,
    choose_source,
    dynamics_episodes,
    dynamics_scores,
    has_score,
    score,
    seen_dynamics,
)


@dataclass
class Comparison:
    """Everything `rllib compare` prints."""

    groups: list[Group]
    sources: dict[str, Source]
    """Per env: where the scores come from."""
    results: list[Paired]
    """Per env and treatment: the overall comparison, then one per dynamics id."""
    notes: list[str] = field(default_factory=list)
    health: dict[str, list[str]] = field(default_factory=dict)
    """Per env: one line per group whose ASOR looks inert (`rllib_asor.report.health`)."""


def load_trials(results_dirs: Sequence[str | os.PathLike[str]], notes: list[str]) -> list[Trial]:
    """Trials under every folder (symlinks followed), each trial folder once."""
    seen: set[str] = set()
    trials: list[Trial] = []
    for d in results_dirs:
        for t in find_trials(d, notes):
            real = os.path.realpath(t.path)
            if real not in seen:
                seen.add(real)
                trials.append(t)
    return trials


def pick_baseline(groups: list[Group], env: str, name: str | None) -> Group:
    """The baseline group of `env`: `name` (a label or a method), else the one without ASOR."""
    mine = [g for g in groups if g.env == env]
    labels = ", ".join(repr(g.label) for g in mine)
    if name:
        hits = [g for g in mine if g.label == name] or [g for g in mine if g.method == name]
        if len(hits) == 1:
            return hits[0]
        what = "several groups match" if hits else "no group is named"
        raise ValueError(f"--baseline {name!r}: {what} in {env}; groups: {labels}")
    plain = [g for g in mine if all(asor_mode(t.params) is None for t in g.trials)]
    if len(plain) == 1:
        return plain[0]
    why = "several groups run without ASOR" if plain else "every group runs ASOR"
    raise ValueError(f"{env}: {why}; choose the baseline with --baseline (groups: {labels})")


def _scores(group: Group, source: Source, last_n: int, notes: list[str]) -> dict:
    out: dict = {}
    for t in group.trials:
        seed = trial_seed(t)
        if seed is None:
            notes.append(f"{t.path}: no seed in params.json, cannot be paired; left out")
        elif seed in out:
            notes.append(f"{t.path}: seed {seed} twice in {group.label!r}; the first kept")
        else:
            out[seed] = score(t, source, last_n)
    return out


def _dynamics(group: Group, source: Source, last_n: int) -> tuple[dict, dict]:
    """Per dynamics id: {seed: score} and {seed: episodes behind it} (where recorded)."""
    scores: dict[str, dict] = {}
    episodes: dict[str, dict] = {}
    seen: set = set()
    for t in group.trials:
        seed = trial_seed(t)
        if seed is None or seed in seen:
            continue  # no seed, or a seed twice (noted by `_scores`): the first trial, as there
        seen.add(seed)
        counts = dynamics_episodes(t, source, last_n)
        for did, value in dynamics_scores(t, source, last_n).items():
            scores.setdefault(did, {})[seed] = value
            if did in counts:
                episodes.setdefault(did, {})[seed] = counts[did]
    return scores, episodes


def _counts(episodes: dict, seeds: list) -> tuple[int | None, int | None]:
    """(total, fewest per trial) of the paired seeds' episode counts; None where unrecorded."""
    got = [episodes[s] for s in seeds if s in episodes]
    if not got or len(got) < len(seeds):
        return None, None
    return sum(got), min(got)


def _unevaluated(source: Source, groups: list[Group], evaluated: set[str]) -> list[str]:
    """Dynamics in the groups' training episodes that no evaluation of theirs has."""
    if source.kind not in EVALUATIONS:
        return []
    seen = {d for g in groups for t in g.trials for d in seen_dynamics(t, TRAIN_KEY)}
    return sorted(seen - evaluated, key=_natural)


def _left_out(env: str, source: Source, trials: list[Trial], notes: list[str]) -> None:
    """One note naming the trials that lack the (evaluation) score the others have."""
    if source.kind not in EVALUATIONS:
        return
    lacking = [t for t in trials if not has_score(t, source)]
    if lacking:
        names = ", ".join(f"{t.path.parent.name}/{t.path.name}" for t in lacking)
        notes.append(
            f"{env}: {len(lacking)} trial(s) left out for lacking evaluations (the others are "
            f"scored by their {source.kind} return, never mixed with training returns): {names}"
        )


def _compare_dynamics(
    res: Paired, base: Group, treat: Group, dyn: tuple, source: Source, last_n: int
) -> list[Paired]:
    """The per-dynamics rows of one comparison, Holm-adjusted together; sets `res`'s lists of
    dynamics evaluated in one arm only or in training only."""
    (base_dyn, base_eps), (treat_dyn, treat_eps) = dyn, _dynamics(treat, source, last_n)
    kw = dict(baseline_name=base.label, treatment_name=treat.label, metric=source.key)
    rows = []
    for did in sorted(base_dyn.keys() & treat_dyn.keys(), key=_natural):
        try:
            d = paired_difference(base_dyn[did], treat_dyn[did], **kw)
        except ValueError:
            continue
        d.env, d.dynamics, d.differs_in, d.arms = res.env, did, res.differs_in, res.arms
        d.withheld, d.smoke = res.withheld, res.smoke
        if d.withheld is not None:
            d.verdict, d.pairs_needed = d.withheld, None
        d.baseline_episodes, d.baseline_min_episodes = _counts(base_eps.get(did, {}), d.seeds)
        d.treatment_episodes, d.treatment_min_episodes = _counts(treat_eps.get(did, {}), d.seeds)
        rows.append(d)
    adjust_dynamics(rows)
    for g, mine, other in ((base, base_dyn, treat_dyn), (treat, treat_dyn, base_dyn)):
        only = sorted(mine.keys() - other.keys(), key=_natural)
        if only:
            res.dynamics_one_arm[g.label] = only
    res.dynamics_training_only = _unevaluated(
        source, [base, treat], base_dyn.keys() | treat_dyn.keys()
    )
    return rows


def compare(
    results_dirs: Sequence[str | os.PathLike[str]],
    baseline: str | None = None,
    metric: str | None = None,
    last_n: int = 1,
) -> Comparison:
    """Read, group and compare the trials under `results_dirs` (ValueError on bad input)."""
    notes: list[str] = []
    trials = load_trials(results_dirs, notes)
    groups = group_trials(trials)
    comp = Comparison(groups=groups, sources={}, results=[], notes=notes)
    envs = {g.env for g in groups}
    for env in sorted(
        e for e in envs if e.endswith(SMOKE_LABEL) and e[: -len(SMOKE_LABEL)] in envs
    ):
        notes.append(
            f"{env[: -len(SMOKE_LABEL)]}: smoke runs (--test) and real runs found together: "
            f"compared apart, the smoke runs under {env!r} with no verdict"
        )
    for env in sorted(envs):
        mine = [g for g in groups if g.env == env]
        if len(mine) < 2:
            notes.append(f"{env}: one group only ({mine[0].label!r}), nothing to compare")
            continue
        base = pick_baseline(groups, env, baseline)
        inert = {g.label: group_health(g.label, [t.rows for t in g.trials]) for g in mine}
        comp.health[env] = [line for line in inert.values() if line]
        every = [t for g in mine for t in g.trials]
        source = choose_source(every, metric)
        comp.sources[env] = source
        _left_out(env, source, every, notes)
        base_scores = _scores(base, source, last_n, notes)
        base_dyn = _dynamics(base, source, last_n)
        smoke = any(is_smoke(t.params) for t in every)
        for g in mine:
            if g is base:
                continue
            kw = dict(baseline_name=base.label, treatment_name=g.label, metric=source.key)
            try:
                res = paired_difference(base_scores, _scores(g, source, last_n, notes), **kw)
            except ValueError as e:
                notes.append(f"{env}: {e} (with a finite score); not compared")
                continue
            res.env, res.differs_in = env, differing_settings(base, g)
            res.arms = arm_account(base, g, res.differs_in)
            res.asor_health = inert[g.label]
            res.smoke, res.withheld = smoke, withheld([base, g], smoke)
            if res.withheld is not None:
                res.verdict, res.pairs_needed = res.withheld, None
            comp.results.append(res)
            comp.results += _compare_dynamics(res, base, g, base_dyn, source, last_n)
    if not comp.results:
        raise ValueError(
            "nothing to compare: "
            + ("; ".join(notes[-3:]) if notes else "fewer than two groups with common seeds")
        )
    return comp


def _natural(key: str) -> tuple:
    try:
        return (0, float(key), key)
    except ValueError:
        return (1, 0.0, key)


def _f(v: float) -> str:
    return "n/a" if not math.isfinite(v) else f"{v:.4g}"


def _seeds(seeds: list) -> str:
    return ", ".join(str(s) for s in seeds)


def render_text(comp: Comparison) -> str:
    """The comparison as text (markdown tables), as `rllib compare` prints it."""
    out: list[str] = []
    for env in sorted({g.env for g in comp.groups}):
        out += [f"## {env}", ""]
        if env in comp.sources:
            out += [f"score: {comp.sources[env].description}", ""]
        out += ["groups (trials differing only in the seed; the keys that define each group):"]
        for g in (g for g in comp.groups if g.env == env):
            seeds = sorted((trial_seed(t) for t in g.trials), key=str)
            keys = ", ".join(f"{k}={v}" for k, v in g.settings.items()) or "(no other keys differ)"
            out.append(f"- {g.label}: {g.n} trial(s), seeds {_seeds(seeds)}; {keys}")
        out.append("")
        main = [r for r in comp.results if r.env == env and r.dynamics is None]
        if not main:
            continue
        out += [
            f"paired by seed; {CI_METHOD}; p: {main[0].test}; P(better): rliable probability "
            "of improvement; IQM: rliable interquartile mean",
            "",
            "| treatment | baseline | pairs | baseline mean | treatment mean | diff | 95% CI "
            "| p | P(better) | IQM base / treat |",
            "|---|---|---|---|---|---|---|---|---|---|",
        ]
        for r in main:
            out.append(_row(r, r.treatment))
        out.append("")
        for r in main:
            out.append(f"{r.treatment} vs {r.baseline} ({r.arms}): {r.verdict}")
        out += comp.health.get(env, [])
        dyn = [r for r in comp.results if r.env == env and r.dynamics is not None]
        if dyn:
            out += [
                "",
                "per dynamics_id:",
                "",
                "| dynamics | treatment | pairs | episodes | min per trial | baseline mean "
                "| treatment mean | diff | 95% CI | p | Holm p | P(better) | decided |",
                "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
            ]
            out += [_dynamics_row(r) for r in dyn]
            out += [
                "",
                "episodes: behind the paired scores, baseline / treatment (min per trial: "
                f"the fewest behind one trial's score; few: < {MIN_EPISODES}); decided: the "
                f"Holm-adjusted p (Holm–Bonferroni over the comparison's dynamics) < {ALPHA:g} "
                "and the 95% interval excludes 0; other rows are exploratory",
            ]
        for r in main:
            lines = _missing_dynamics(r, comp.sources[env])
            if lines:
                out.append(f"{r.treatment} vs {r.baseline}: {lines}")
        out.append("")
    if comp.notes:
        out += ["notes:"] + [f"- {n}" for n in comp.notes]
    return "\n".join(out).rstrip() + "\n"


def _pair(a: int | None, b: int | None) -> str:
    return "n/a" if a is None or b is None else f"{a} / {b}"


def _dynamics_row(r: Paired) -> str:
    few = " (few)" if r.few_episodes else ""
    if r.withheld:
        state = "no verdict"
    elif decided(r):
        state = f"decided: {'better' if r.ci_low > 0 else 'worse'}"
    else:
        state = "exploratory"
    cells = [r.dynamics or "", r.treatment, str(r.pairs),
             _pair(r.baseline_episodes, r.treatment_episodes),
             _pair(r.baseline_min_episodes, r.treatment_min_episodes) + few,
             _f(r.baseline_mean), _f(r.treatment_mean), f"{r.diff_mean:+.4g}",
             f"[{_f(r.ci_low)}, {_f(r.ci_high)}]", _f(r.p_value), _f(r.p_adjusted),
             _f(r.prob_improvement), state]  # fmt: skip
    return "| " + " | ".join(cells) + " |"


def _missing_dynamics(r: Paired, source: Source) -> str:
    """The dynamics of a comparison that one arm (or every evaluation) lacks, in one line."""
    evaluated = source.kind in EVALUATIONS
    parts = [
        f"{', '.join(ids)} ({'evaluated in ' if evaluated else ''}{label} only)"
        for label, ids in r.dynamics_one_arm.items()
    ]
    if r.dynamics_training_only:
        parts.append(f"{', '.join(r.dynamics_training_only)} (in training, in no evaluation)")
    if not parts:
        return ""
    what = "evaluation episodes" if evaluated else "episodes in both arms"
    return f"dynamics without {what}: {'; '.join(parts)}"


def _row(r: Paired, head: str) -> str:
    ci = f"[{_f(r.ci_low)}, {_f(r.ci_high)}]"
    cells = [head] if "|" in head else [head, r.baseline]
    cells += [str(r.pairs), _f(r.baseline_mean), _f(r.treatment_mean), f"{r.diff_mean:+.4g}", ci,
              _f(r.p_value), _f(r.prob_improvement), f"{_f(r.baseline_iqm)} / {_f(r.treatment_iqm)}"]  # fmt: skip
    return "| " + " | ".join(cells) + " |"
