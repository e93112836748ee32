"""`rllib train ... --dry-run` (or `--print-config`): what a file becomes on the new API stack.

Every experiment is translated and validated exactly as for training, but Ray never starts:
the warnings (one per translated key) and the resulting experiment in the new YAML format are
printed, ready to be saved as a file that runs without warnings.
"""

from __future__ import annotations

import sys
from typing import Any

import yaml

from rllib_asor.cli import experiment


def _plain(value: Any) -> Any:
    """YAML-safe: callables (e.g. a connector factory) as 'module:qualname'."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_plain(v) for v in value]
    if callable(value):
        return f"{getattr(value, '__module__', '?')}:{getattr(value, '__qualname__', value)}"
    return value


def as_yaml(exp: experiment.Experiment) -> str:
    """The translated experiment in the new-stack YAML format."""
    config = dict(exp.config)
    if exp.asor is not None:
        config["asor"] = exp.asor
    spec: dict[str, Any] = {"env": exp.env, "run": exp.run, "stop": exp.stop, "config": config}
    if exp.checkpoint_config:
        spec["checkpoint_config"] = exp.checkpoint_config
    if exp.num_samples != 1:
        spec["num_samples"] = exp.num_samples
    return yaml.safe_dump({exp.name: _plain(spec)}, sort_keys=False, default_flow_style=None)


def print_experiments(exps: list[experiment.Experiment]) -> None:
    """Warnings on stderr, then the new-stack YAML of every experiment on stdout."""
    for exp in exps:
        for warning in dict.fromkeys(exp.warnings):
            print(f"rllib: warning: {warning}", file=sys.stderr)
    print("# the new-stack experiment(s): translated and validated, Ray not started")
    for exp in exps:
        print(as_yaml(exp), end="")
