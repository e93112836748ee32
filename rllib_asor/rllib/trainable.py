"""Tune trainables whose config dict may carry an `"asor"` block.

`rllib train file X.yaml` builds `param_space = algo_config.to_dict()` plus `"asor": {...}`;
Tune resolves `grid_search` anywhere in it (λ, ρ1, ρ2, seeds), and each trial applies
`with_asor` with its concrete values here. The classes are module-level so checkpoints
pickle them by reference.
"""

from __future__ import annotations

from typing import Any

from ray.rllib.algorithms.algorithm import Algorithm
from ray.tune.registry import get_trainable_cls

from rllib_asor.algorithms.ppo.overlap import OverlappedPPO
from rllib_asor.registry.algorithms import register_algorithms
from rllib_asor.rllib.wiring import SUPPORTED, supported_run, with_asor

ASOR_KEY = "asor"


def _asor_init(base: type[Algorithm]) -> Any:
    def __init__(self: Algorithm, config: Any = None, *args: Any, **kwargs: Any) -> None:
        if isinstance(config, dict) and ASOR_KEY in config:
            config = dict(config)
            settings = config.pop(ASOR_KEY)
            if settings is not None:  # None: no block, the plain algorithm (`rllib ab`'s baseline)
                algo_config = base.get_default_config().update_from_dict(config)
                config = with_asor(algo_config, **settings)
        base.__init__(self, config, *args, **kwargs)

    return __init__


def asor_trainable(run: str) -> type[Algorithm]:
    """The Algorithm class for `run` ("PPO", ...) that applies an `"asor"` config block; a
    block that is None leaves the plain algorithm (one trainable for both arms of `rllib ab`)."""
    if supported_run(run) is None:  # SUPPORTED or a subclass of one (FastSAC)
        raise ValueError(
            f"ASOR does not support run={run!r}: supported {', '.join(sorted(SUPPORTED))}"
        )
    name = f"Asor{run}"
    cls = globals().get(name)
    if cls is None:
        # PPO: `OverlappedPPO`, which is RLlib's PPO unless the config switches the overlap on.
        register_algorithms()  # MAPLE
        base = OverlappedPPO if run == "PPO" else get_trainable_cls(run)
        cls = type(
            name,
            (base,),
            {"__init__": _asor_init(base), "__module__": __name__, "__qualname__": name},
        )
        globals()[name] = cls
    return cls


def __getattr__(name: str) -> Any:
    """Unpickling `rllib_asor.rllib.trainable.AsorPPO` recreates the class on demand."""
    if name.startswith("Asor") and supported_run(name[4:]) is not None:
        return asor_trainable(name[4:])
    raise AttributeError(name)
