"""`rllib compare`: every treatment group against the baseline, paired by seed, per env and per
``dynamics_id``. Reading is `results`, grouping `grouping`, the score `scores`, statistics
`paired`; this module puts them together and renders the text."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field

from rllib_asor.report.grouping import Group, differing_settings, group_trials, trial_seed
from rllib_asor.report.health import group_health
from rllib_asor.report.paired import CI_METHOD, Paired, paired_difference
from rllib_asor.report.results import Trial, asor_mode, find_trials
from rllib_asor.report.scores import Source, choose_source, dynamics_scores, score


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


def _dynamics(group: Group, source: Source, last_n: int) -> dict[str, dict]:
    out: dict[str, dict] = {}
    for t in group.trials:
        seed = trial_seed(t)
        for did, value in dynamics_scores(t, source, last_n).items():
            out.setdefault(did, {}).setdefault(seed, value)
    return out


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
    for env in sorted({g.env for g in groups}):
        mine = [g for g in groups if g.env == env]
        if len(mine) < 2:
            notes.append(f"{env}: one group only ({mine[0].label!r}), nothing to compare")
            continue
        base = pick_baseline(groups, env, baseline)
        inert = {g.label: group_health(g.label, [t.rows for t in g.trials]) for g in mine}
        comp.health[env] = [line for line in inert.values() if line]
        source = choose_source([t for g in mine for t in g.trials], metric)
        comp.sources[env] = source
        base_scores = _scores(base, source, last_n, notes)
        base_dyn = _dynamics(base, source, last_n)
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
            res.asor_health = inert[g.label]
            comp.results.append(res)
            treat_dyn = _dynamics(g, source, last_n)
            for did in sorted(base_dyn.keys() & treat_dyn.keys(), key=_natural):
                try:
                    dres = paired_difference(base_dyn[did], treat_dyn[did], **kw)
                except ValueError:
                    continue
                dres.env, dres.dynamics, dres.differs_in = env, did, res.differs_in
                comp.results.append(dres)
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
            out.append(f"{r.treatment} vs {r.baseline} (differs in: {', '.join(r.differs_in)}): "
                       f"{r.verdict}")  # fmt: skip
        out += comp.health.get(env, [])
        dyn = [r for r in comp.results if r.env == env and r.dynamics is not None]
        if dyn:
            out += [
                "",
                "per dynamics_id:",
                "",
                "| dynamics | treatment | pairs | baseline mean | treatment mean | diff | 95% CI "
                "| p | P(better) | IQM base / treat |",
                "|---|---|---|---|---|---|---|---|---|---|",
            ]
            out += [_row(r, f"{r.dynamics} | {r.treatment}") for r in dyn]
        out.append("")
    if comp.notes:
        out += ["notes:"] + [f"- {n}" for n in comp.notes]
    return "\n".join(out).rstrip() + "\n"


def _row(r: Paired, head: str) -> str:
    ci = f"[{_f(r.ci_low)}, {_f(r.ci_high)}]"
    cells = [head] if "|" in head else [head, r.baseline]
    cells += [str(r.pairs), _f(r.baseline_mean), _f(r.treatment_mean), f"{r.diff_mean:+.4g}", ci,
              _f(r.p_value), _f(r.prob_improvement), f"{_f(r.baseline_iqm)} / {_f(r.treatment_iqm)}"]  # fmt: skip
    return "| " + " | ".join(cells) + " |"
