"""Algorithm names of ours for Tune and the CLI (`run: MAPLE`), next to RLlib's own.

`register_algorithms()` registers each with `ray.tune.register_trainable` (idempotent; cheap
after the first call), so `get_trainable_cls("MAPLE")` and `rllib train` find them.
"""

from __future__ import annotations

import importlib

from rllib_asor import ray_compat as compat

ALGORITHMS = {
    "MAPLE": "rllib_asor.algorithms.maple.maple:MAPLE",
    "MOPO": "rllib_asor.algorithms.maple.maple:MOPO",
    "ESCP": "rllib_asor.algorithms.escp.config:ESCP",
    "OSI": "rllib_asor.algorithms.osi.config:OSI",  # universal policy + system identification
    "CaDM": "rllib_asor.algorithms.cadm.config:CaDM",  # context-aware dynamics model (model-free)
    "FastSAC": "rllib_asor.algorithms.sac.config:FastSAC",  # SAC on the fast off-policy path
    "GAIfO": "rllib_asor.algorithms.gaifo.config:GAIfO",  # adversarial imitation from observation
    "GARAT": "rllib_asor.algorithms.garat.config:GARAT",  # grounded action transformation
    "BCO": "rllib_asor.algorithms.bco.config:BCO",  # behavioural cloning from observation
    "SOIL": "rllib_asor.algorithms.soil.config:SOIL",  # PPO + IDM-inferred imitation term
}
"""Run name → "module:Class"."""


def run_names() -> list[str]:
    """Every `run:` name, sorted: RLlib's registered algorithms and ours (what `rllib schema`
    and the CLI's "allowed" lists name)."""
    from ray.rllib.algorithms.registry import ALGORITHMS as RLLIB

    return sorted(set(RLLIB) | set(ALGORITHMS))


def algorithm(name: str) -> type:
    """The Algorithm class of one of our run names."""
    module, _, cls = ALGORITHMS[name].partition(":")
    return getattr(importlib.import_module(module), cls)


def register_algorithms() -> None:
    """Register our algorithms with Tune (once per process)."""
    from ray.tune.registry import TRAINABLE_CLASS, register_trainable

    for name in ALGORITHMS:
        if not compat.tune_registry_contains(TRAINABLE_CLASS, name):
            register_trainable(name, algorithm(name))
