"""Grouping trials so that a group is one method's seeds and nothing else.

Two trials are seeds of one group only when their settings (``params.json``, flattened to dotted
keys) differ in the seed alone: every other key whose value differs between trials of one env
defines separate groups. A group's label is its method (``PPO+ASOR``; with ``group_by``,
``KEY=value``; with the ``rllib ab`` arm key, the arm's name) plus the keys that tell it apart
from the other groups of the same method, e.g. ``PPO+ASOR (asor.lambda_=0.1)``.
"""

from __future__ import annotations

import json
import re
from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

from rllib_asor.report.results import (
    RUN_KEY,
    SMOKE_KEY,
    Trial,
    asor_block,
    asor_mode,
    assign_groups,
)

SEED_NAMES = frozenset({"seed"})
"""Last component of a params key that holds a seed (``seed``, ``env_config.seed``, ...)."""

ARM_KEY = "rllib_asor_arm"
"""Params key with which `rllib ab` names each arm; when present it is the group's label."""

IGNORED_KEYS = frozenset({RUN_KEY, ARM_KEY, SMOKE_KEY})
"""Bookkeeping keys: they never define a group nor show in ``differs in`` (the algorithm and the
arm are the group's label, a smoke run its env's label)."""

CALLBACKS_KEY = "callbacks"
METRICS_ONLY_CALLBACKS = frozenset(
    {
        "rllib_asor.rllib.callbacks.AsorMetricsCallback",
        "rllib_asor.rllib.callbacks.DropNaNLearnerStatsCallback",
        "rllib_asor.evaluation.dynamics.DynamicsReturnsCallback",
        "ray.rllib.callbacks.callbacks.RLlibCallback",
    }
)
"""Callbacks that only add metrics (or, RLlib's bare default, do nothing): trials that differ in
them alone are the same method (`rllib_asor.rllib.wiring.METRICS_CALLBACKS` and the per-dynamics
returns callback `rllib ab` adds)."""

_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
_CLASS = re.compile(r"<class '([\w.]+)'>")
_DOTTED = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)+$")
_QUALIFIED = re.compile(r"\b(?:[A-Za-z_]\w*\.)+([A-Z]\w*)\b")
_MISSING = "<missing>"
_LABEL_VALUE_CHARS = 40


@dataclass
class Group:
    """Trials of one env that differ in the seed only."""

    env: str
    label: str
    method: str
    settings: dict[str, str]
    """The keys (and values) that tell this group apart from the other groups of its env."""
    trials: list[Trial] = field(default_factory=list)

    @property
    def n(self) -> int:
        return len(self.trials)


def flat_params(params: dict[str, Any], prefix: str = "") -> Iterator[tuple[str, str]]:
    """``("a.b.c", canonical JSON of the value)`` for every leaf of a params dict.

    A None or empty-dict value counts as not set. Object reprs lose their memory address (Tune writes objects it cannot serialise as their
    repr, e.g. ``<function f at 0x7f...>``), so the same setting compares equal across trials.
    """
    for key, value in params.items():
        dotted = f"{prefix}{key}"
        if value is None or value == {}:
            continue  # the same as not set
        if isinstance(value, dict):
            yield from flat_params(value, dotted + ".")
        else:
            text = json.dumps(value, sort_keys=True, default=str)
            yield dotted, _ADDRESS.sub("", text)


def trial_settings(params: dict[str, Any]) -> dict[str, str]:
    """`flat_params` of a trial, its ASOR block always under ``asor.`` (`rllib train` writes it
    at the top level, `with_asor` configs under ``learner_config_dict``: the same setting)."""
    params = dict(params)
    block = asor_block(params)
    lcd = params.get("learner_config_dict")
    if isinstance(lcd, dict) and "asor" in lcd:
        params["learner_config_dict"] = {k: v for k, v in lcd.items() if k != "asor"}
    if block is not None:
        params["asor"] = block
    if CALLBACKS_KEY in params:
        kept = [c for c in callback_names(params[CALLBACKS_KEY]) if c not in METRICS_ONLY_CALLBACKS]
        params[CALLBACKS_KEY] = kept or None
    return dict(flat_params(params))


def callback_names(value: Any) -> list[str]:
    """The callback classes in a params ``callbacks`` value (one or a list; Tune writes classes as
    ``<class 'pkg.mod.Name'>``, a YAML file as ``pkg.mod.Name``) as dotted names; other values
    (a function's repr, ...) as they are."""
    out = []
    for item in value if isinstance(value, list | tuple) else [value]:
        if item is None:
            continue
        text = str(item)
        found = _CLASS.fullmatch(text)
        out.append(found.group(1) if found else text)
    return out


def is_seed_key(key: str) -> bool:
    """Whether a dotted params key holds a seed (differences in it do not split groups)."""
    return key.rsplit(".", 1)[-1] in SEED_NAMES


def trial_seed(trial: Trial) -> Any:
    """The trial's seed: ``params["seed"]``, else the first ``*.seed`` key; None if none."""
    flat = trial_settings(trial.params)
    if "seed" in flat:
        return json.loads(flat["seed"])
    for key in sorted(flat):
        if is_seed_key(key):
            return json.loads(flat[key])
    return None


def short_value(text: str, limit: int = _LABEL_VALUE_CHARS) -> str:
    """A setting's value (canonical JSON) as labels show it: classes by their name, and when
    longer than `limit`, cut after the last whole word that fits (``…``), never inside a name."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = text
    shown = value if isinstance(value, str) else json.dumps(value)
    shown = _QUALIFIED.sub(r"\1", _CLASS.sub(r"\1", shown))
    if len(shown) <= limit:
        return shown
    cut = shown[: limit - 1]
    if shown[limit - 1].isalnum() or shown[limit - 1] == "_":  # inside a word: back to its start
        start = re.search(r"\w*$", cut)
        cut = cut[: start.start()] if start else cut
    cut = cut.rstrip(" ,.:;=/-")
    return cut + "…" if cut.strip("[{(\"' ") else shown


def varying_keys(trials: Iterable[Trial]) -> list[str]:
    """Params keys (not seeds) whose value differs between `trials`, or is missing in some."""
    flats = [trial_settings(t.params) for t in trials]
    keys = sorted({k for f in flats for k in f})
    return [
        k
        for k in keys
        if not is_seed_key(k)
        and k not in IGNORED_KEYS
        and len({f.get(k, _MISSING) for f in flats}) > 1
    ]


def group_trials(trials: list[Trial], group_by: str | None = None) -> list[Group]:
    """Split `trials` into groups that differ in more than the seed (see the module doc).

    Sets each trial's ``env`` and ``method`` (``method`` becomes the group's full label).
    Groups come sorted by env, then label.
    """
    assign_groups(trials, group_by)
    for t in trials:
        arm = t.params.get(ARM_KEY)
        if isinstance(arm, str) and arm and not group_by:
            t.method = arm
    groups: list[Group] = []
    for env in sorted({t.env for t in trials}):
        members = [t for t in trials if t.env == env]
        keys = varying_keys(members)
        by_setting: dict[tuple[str, tuple[str, ...]], list[Trial]] = {}
        for t in members:
            flat = trial_settings(t.params)
            by_setting.setdefault(
                (t.method, tuple(flat.get(k, _MISSING) for k in keys)), []
            ).append(t)
        for method in sorted({m for m, _ in by_setting}):
            variants = {vals: ts for (m, vals), ts in by_setting.items() if m == method}
            # Label with the keys that differ between this method's groups.
            own = [i for i, _ in enumerate(keys) if len({v[i] for v in variants}) > 1]
            for vals, ts in sorted(variants.items()):
                # A key the group does not set is left out of its label (listed in `settings`).
                shown = [f"{keys[i]}={short_value(vals[i])}" for i in own if vals[i] != _MISSING]
                label = f"{method} ({', '.join(shown)})" if shown else method
                for t in ts:
                    t.method = label
                groups.append(
                    Group(
                        env=env,
                        label=label,
                        method=method,
                        settings={k: short_value(v) for k, v in zip(keys, vals, strict=True)},
                        trials=sorted(ts, key=lambda t: str(t.path)),
                    )
                )
    return groups


def differing_settings(a: Group, b: Group) -> list[str]:
    """Keys whose value differs between two groups of one env (what a comparison compares)."""
    return sorted(
        k for k in a.settings.keys() | b.settings.keys() if a.settings.get(k) != b.settings.get(k)
    )


def _runs_asor(g: Group) -> bool:
    return any(asor_mode(t.params) is not None for t in g.trials)


def arm_account(base: Group, treat: Group, differs: list[str]) -> str:
    """How two groups differ, in `rllib ab`'s words (`rllib_asor.cli.ab.arm_check`): "the arms
    differ only in ASOR" when one runs ASOR and the other not and nothing else differs,
    "besides ASOR, the arms differ in: ..." when more does, else "the arms differ in: ..."."""
    other = [k for k in differs if k != "asor" and not k.startswith("asor.")]
    if _runs_asor(base) != _runs_asor(treat):
        if not other:
            return "the arms differ only in ASOR"
        return f"besides ASOR, the arms differ in: {', '.join(other)}"
    if not differs:
        return "the arms differ in no recorded setting"
    return f"the arms differ in: {', '.join(differs)}"
