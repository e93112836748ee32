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

from rllib_asor.report.results import Trial, asor_block, assign_groups

SEED_NAMES = frozenset({"seed"})
"""Last component of a params key that holds a seed (``seed``, ``env_config.seed``, ...)."""

ARM_KEY = "rllib_asor_arm"
"""Params key with which `rllib ab` names each arm; when present it is the group's label."""

IGNORED_KEYS = frozenset({"rllib_asor_run"})
"""Keys that never define a group by themselves (the algorithm is in the method label)."""

_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
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
    return dict(flat_params(params))


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


def _short_value(text: str) -> str:
    try:
        value = json.loads(text)
    except json.JSONDecodeError:
        value = text
    shown = value if isinstance(value, str) else json.dumps(value)
    return shown if len(shown) <= _LABEL_VALUE_CHARS else shown[: _LABEL_VALUE_CHARS - 1] + "…"


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
                shown = [f"{keys[i]}={_short_value(vals[i])}" for i in own if vals[i] != _MISSING]
                label = f"{method} ({', '.join(shown)})" if shown else method
                for t in ts:
                    t.method = label
                groups.append(
                    Group(
                        env=env,
                        label=label,
                        method=method,
                        settings={k: _short_value(v) for k, v in zip(keys, vals, strict=True)},
                        trials=sorted(ts, key=lambda t: str(t.path)),
                    )
                )
    return groups


def differing_settings(a: Group, b: Group) -> list[str]:
    """Keys whose value differs between two groups of one env (what a comparison compares)."""
    return sorted(
        k for k in a.settings.keys() | b.settings.keys() if a.settings.get(k) != b.settings.get(k)
    )
