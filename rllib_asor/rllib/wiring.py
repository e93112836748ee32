"""`with_asor(config, **settings)`: switch ASOR on for an RLlib AlgorithmConfig.

What it wires in:
- the algorithm's ASOR Learner class (PPO: `AsorPPOTorchLearner`),
- per trained policy one `learner_only` module in the MultiRLModule (`asor_disc.<policy>`, an
  `AsorModule`: the policy's `AsorTrainer` with the discriminator, the proxy and their
  optimisers; ASOR's piece trains it, RLlib only builds, places and checkpoints it),
- the validated settings in `learner_config_dict["asor"]` (pickled into every Learner and
  checkpoint),
- a callback that lifts the Learner's ASOR statistics to `asor/...` in the results.

Nothing else: the RLModule class, replay buffer, critics and update rhythm stay those of
`config`. The ASOR Learner is a subclass of the Learner `config` would use (`asor_learner_class`):
RLlib's `SACTorchLearner` for a stock `SACConfig()`, `FastSACTorchLearner` for a
`FastSACConfig()` (rllib_asor/algorithms/sac/config.py, the fast off-policy path as a choice
made for both arms).
"""

from __future__ import annotations

import copy
import dataclasses
import warnings
from typing import Any

from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.callbacks.callbacks import RLlibCallback
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModule, MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.callbacks import add_callbacks
from rllib_asor.algorithms.sac.fast import FAST_KEY, FLAT_STORAGE
from rllib_asor.algorithms.sac.learner import FastSACTorchLearner
from rllib_asor.asor.config import ALGORITHMS, AsorConfig
from rllib_asor.registry.env_names import register_env
from rllib_asor.rllib.callbacks import AsorMetricsCallback, DropNaNLearnerStatsCallback
from rllib_asor.rllib.learners import (
    ASOR_LEARNERS,
    AsorCQLTorchLearner,
    AsorESCPTorchLearner,
    AsorLearnerMixin,
    AsorMapleTorchLearner,
    AsorPPOTorchLearner,
    AsorSACTorchLearner,
    asor_module_id,
    is_aux_module,
)
from rllib_asor.rllib.modules import AsorModule

SUPPORTED = {
    "PPO": AsorPPOTorchLearner,
    "SAC": AsorSACTorchLearner,
    "CQL": AsorCQLTorchLearner,
    "MAPLE": AsorMapleTorchLearner,  # MOPO too (a MAPLE subclass)
    "ESCP": AsorESCPTorchLearner,  # ESCP+ASOR, the paper's Algorithm 1
}
assert tuple(sorted(SUPPORTED)) == ALGORITHMS, "one list of supported algorithms (asor.config)"

SPECIFIC = tuple(c for c in ASOR_LEARNERS if c not in SUPPORTED.values())
"""ASOR Learners on Learners of ours (`LeanPPOTorchLearner`, `FastSACTorchLearner`), tried after
`SUPPORTED`'s: `asor_learner_class` takes the first that subclasses the config's Learner."""


class AsorMultiRLModuleSpec(MultiRLModuleSpec):
    """A MultiRLModuleSpec whose ASOR modules inherit their policy's spaces at build time.

    RLlib fills missing spaces only for policies; ASOR's module `asor_disc.<pid>` takes the
    observation/action space of `<pid>`.
    """

    def build(self, module_id: str | None = None) -> Any:
        for mid, spec in self.rl_module_specs.items():
            if is_aux_module(mid):
                policy = self.rl_module_specs.get(mid.split(".", 1)[1])
                if policy is not None:
                    spec.observation_space = spec.observation_space or policy.observation_space
                    spec.action_space = spec.action_space or policy.action_space
        return super().build(module_id)


def with_asor(config: AlgorithmConfig, **settings: Any) -> AlgorithmConfig:
    """Return a copy of `config` (PPO, SAC, CQL, ESCP, MAPLE or MOPO; new API stack, torch)
    with ASOR wired in.

    `settings` are `AsorConfig` fields; none at all gives the robust default,
    `preset="paper"` the published form. Example:
    `with_asor(PPOConfig().environment("rllib_asor/LavaWorld-v0"), lambda_=0.1, seed=0)`.
    Raises ValueError (naming the key, the value and what is allowed) for unsupported
    algorithms, the old API stack, or bad settings.
    """
    asor = AsorConfig.from_dict(settings)
    if not isinstance(config, AlgorithmConfig):
        raise ValueError(f"with_asor needs an RLlib AlgorithmConfig, got {type(config).__name__}")
    algo = _algorithm_name(config)
    if algo not in SUPPORTED:
        raise ValueError(
            f"ASOR does not support algorithm {algo!r}: supported {', '.join(sorted(SUPPORTED))}"
        )
    if not config.enable_rl_module_and_learner:
        raise ValueError("ASOR needs RLlib's new API stack (enable_rl_module_and_learner=True)")
    if config.framework_str != "torch":
        raise ValueError(f"ASOR needs framework='torch', got {config.framework_str!r}")

    learner_class = asor_learner_class(config, algo)
    _check_infos(config, asor)
    _note_slow_sac(config, learner_class, asor)
    config = config.copy(copy_frozen=False)
    if isinstance(config.env, str):
        register_env(config.env)  # env runners (other processes, nodes) can then build it
    asor_dict = asor.to_dict()
    config.rl_module(rl_module_spec=_module_spec(config, asor))
    config.learners(
        learner_class=learner_class,
        learner_config_dict={"asor": asor_dict},  # RLlib merges it into the user's dict
    )
    add_callbacks(config, AsorMetricsCallback)
    if config.policies_to_train is not None:  # single-agent configs may set it too
        config.multi_agent(policies_to_train=_AlsoTrainAux(config.policies_to_train))
    return config


SLOW_SAC_NOTE = (
    "with_asor(SACConfig()) wraps RLlib's own SAC Learner, several times slower per env step "
    "than rllib_asor.FastSACConfig(), the same SAC on the fast off-policy path (docs/speed.md); "
    "learner_config_dict={'fast_off_policy': False} keeps RLlib's without this note"
)


def _note_slow_sac(config: AlgorithmConfig, learner_class: type, asor: AsorConfig) -> None:
    """One warning (Python shows it once per place) when ASOR goes on RLlib's own SAC and
    nothing chose that: not for FastSACConfig, not for a config that records its path
    (`rllib train`'s `run: SAC` or an opt-out), not where the fast path cannot run ASOR
    (per-dynamics RND)."""
    from ray.rllib.algorithms.sac import SAC

    chose = FAST_KEY in (config.learner_config_dict or {})
    per_dynamics = asor.needs_proxy and asor.proxy == "rnd_per_dynamics"
    if config.algo_class is SAC and learner_class is AsorSACTorchLearner and not (
        chose or per_dynamics
    ):
        warnings.warn(SLOW_SAC_NOTE, UserWarning, stacklevel=3)


def _check_infos(config: AlgorithmConfig, asor: AsorConfig) -> None:
    """Per-dynamics RND needs each step's dynamics id, which the fast path's flat replay
    buffer does not keep: refuse that pair in one line."""
    if not (asor.needs_proxy and asor.proxy == "rnd_per_dynamics"):
        return
    base = compat.user_learner_class(config) or config.get_default_learner_class()
    rb = getattr(config, "replay_buffer_config", None) or {}  # on-policy configs have none
    flat = rb.get("storage") == FLAT_STORAGE or (
        issubclass(base, FastSACTorchLearner) and rb.get("type") == "EpisodeReplayBuffer"
    )
    if flat:
        raise ValueError(
            "proxy='rnd_per_dynamics' needs each step's dynamics id, which the fast path's flat "
            "replay buffer does not keep; allowed: another proxy, or RLlib's replay (SACConfig(); "
            "in YAML run: SAC with learner_config_dict: {fast_off_policy: false})"
        )


def supported_run(run: str) -> str | None:
    """The supported algorithm ("SAC") that a Tune run name ("SAC", "FastSAC") is or derives
    from; None for other names and unknown ones."""
    if run in SUPPORTED:
        return run
    from ray.tune.registry import get_trainable_cls

    from rllib_asor.registry.algorithms import register_algorithms

    register_algorithms()
    try:
        cls = get_trainable_cls(run)
    except Exception:  # unknown name: the caller names what is allowed
        return None
    return next((c.__name__ for c in getattr(cls, "__mro__", ()) if c.__name__ in SUPPORTED), None)


def _algorithm_name(config: AlgorithmConfig) -> str:
    """ "PPO", "SAC", ... for the config's algorithm or a subclass of one (`OverlappedPPO`)."""
    cls = config.algo_class
    if cls is None:
        return type(config).__name__
    return next((c.__name__ for c in cls.__mro__ if c.__name__ in SUPPORTED), cls.__name__)


def asor_learner_class(config: AlgorithmConfig, algo: str | None = None) -> type:
    """The ASOR Learner for `config`: a subclass of the Learner it would use without ASOR
    (the user's `learner_class`, else the config's default), so ASOR adds to that Learner and
    changes nothing of it. A Learner that already has ASOR is kept (`with_asor` twice).

    A Learner of the user's with no ASOR subclass here gets the algorithm's ASOR Learner if
    that has every base class of the user's (e.g. `LeanPPOTorchLearner`, whose mixin
    `AsorPPOTorchLearner` has); otherwise ValueError names it and what is allowed.
    """
    algo = algo or _algorithm_name(config)
    base = compat.user_learner_class(config) or config.get_default_learner_class()
    if isinstance(base, type) and issubclass(base, AsorLearnerMixin):
        return base
    default = SUPPORTED[algo]
    for candidate in (default, *SPECIFIC):
        if issubclass(candidate, base):
            return candidate
    own = [name for name in vars(base) if not name.startswith("__") and name != "_abc_impl"]
    if not own and all(c in default.__mro__ for c in base.__mro__[1:]):
        return default  # the user's class adds nothing of its own to bases ASOR's has
    raise ValueError(
        f"learner_class={base.__name__} has no ASOR Learner: with_asor would replace it; "
        f"allowed: leave learner_class unset, or a subclass of {default.__name__} "
        f"(rllib_asor.rllib.learners) or of {', '.join(c.__name__ for c in SPECIFIC)}"
    )


class _AlsoTrainAux:
    """`policies_to_train` that keeps the user's choice and always trains ASOR's modules."""

    def __init__(self, user: Any) -> None:
        self.user = user.user if isinstance(user, _AlsoTrainAux) else user

    def __call__(self, module_id: str, batch: Any = None) -> bool:
        if is_aux_module(module_id):
            return True
        if callable(self.user):
            return bool(self.user(module_id, batch))
        return module_id in set(self.user)


def trained_policy_ids(config: AlgorithmConfig) -> list[str]:
    """The policies ASOR regularises: all trained ones (single-agent: the default policy)."""
    if not config.is_multi_agent:
        return [DEFAULT_MODULE_ID]
    pids = list(config.policies)
    to_train = config.policies_to_train
    if isinstance(to_train, _AlsoTrainAux):
        to_train = to_train.user
    if to_train is not None and not callable(to_train):
        pids = [p for p in pids if p in set(to_train)]
    return pids


def _module_spec(config: AlgorithmConfig, asor: AsorConfig) -> AsorMultiRLModuleSpec:
    existing = compat.user_rl_module_spec(config)
    pids = trained_policy_ids(config)
    all_pids = list(config.policies) if config.is_multi_agent else [DEFAULT_MODULE_ID]
    keep: dict[str, Any] = {}
    if isinstance(existing, MultiRLModuleSpec):
        specs = {m: s for m, s in existing.rl_module_specs.items() if not is_aux_module(m)}
        # the user's own settings of the spec (a custom MultiRLModule class, its config)
        fields = [f.name for f in dataclasses.fields(MultiRLModuleSpec) if f.name != "module_specs"]
        keep = {name: getattr(existing, name) for name in fields}
    elif isinstance(existing, RLModuleSpec):
        specs = {pid: copy.deepcopy(existing) for pid in all_pids}
    else:
        specs = {pid: RLModuleSpec() for pid in all_pids}
    model_config = {"asor": asor.to_dict()}
    for pid in pids:
        policy_spec = config.policies.get(pid) if config.is_multi_agent else None
        spaces = {
            "observation_space": getattr(policy_spec, "observation_space", None),
            "action_space": getattr(policy_spec, "action_space", None),
        }
        specs[asor_module_id(pid)] = RLModuleSpec(
            module_class=AsorModule, learner_only=True, model_config=dict(model_config), **spaces
        )
    return AsorMultiRLModuleSpec(**{**keep, "rl_module_specs": specs})


# ------------------------------------------------------------------ arms that differ in ASOR
ADDED_KEYS = (
    compat.TO_DICT_KEYS["learner_class"],
    "learner_config_dict",
    compat.TO_DICT_KEYS["rl_module"],
    "callbacks",
    "policies_to_train",
)
"""`AlgorithmConfig.to_dict()` keys that `with_asor` sets; `arm_differences` checks each."""
METRICS_CALLBACKS = (AsorMetricsCallback, DropNaNLearnerStatsCallback)
"""Metrics-only callbacks: `with_asor` adds the first, a run without ASOR may have the second."""


def arm_differences(base: AlgorithmConfig, treated: AlgorithmConfig) -> list[str]:
    """The settings in which `treated` (a config with ASOR) differs from `base` (without it)
    beyond what `with_asor` adds; [] when the two arms differ only in ASOR.

    What `with_asor` may add: `learner_config_dict["asor"]`, the Learner
    `asor_learner_class(base)`, ASOR's module specs beside the unchanged
    policy specs, `AsorMetricsCallback`, and `policies_to_train` that also trains its modules.
    """
    a, b = base.to_dict(), treated.to_dict()
    out = [
        k for k in sorted(set(a) | set(b)) if k not in ADDED_KEYS and not _same(a.get(k), b.get(k))
    ]
    if treated.learner_class is not asor_learner_class(base):
        out.append("learner_class")
    lcd = {k: v for k, v in (treated.learner_config_dict or {}).items() if k != "asor"}
    if not _same(lcd, dict(base.learner_config_dict or {})):
        out.append("learner_config_dict")
    if _plain_callbacks(base) != _plain_callbacks(treated):
        out.append("callbacks")
    if not _same(_policy_specs(base), _policy_specs(treated)):
        out.append("rl_module_spec")
    user = treated.policies_to_train
    if not _same(user.user if isinstance(user, _AlsoTrainAux) else user, base.policies_to_train):
        out.append("policies_to_train")
    return out


def _same(x: Any, y: Any) -> bool:
    try:
        return bool(x == y)
    except Exception:  # arrays and the like: compare what they print
        return repr(x) == repr(y)


def _plain_callbacks(config: AlgorithmConfig) -> list[type]:
    cbs = config.callbacks_class
    cbs = list(cbs) if isinstance(cbs, list | tuple) else [cbs]
    return [c for c in cbs if c not in (*METRICS_CALLBACKS, RLlibCallback, None)]


def _policy_specs(config: AlgorithmConfig) -> dict[str, tuple]:
    """Each policy's module class (the config's default where unset), catalog, model config
    and spaces, without ASOR's modules; the multi-module class of a user's MultiRLModuleSpec."""
    spec = compat.user_rl_module_spec(config)
    default = config.get_default_rl_module_spec()
    pids = list(config.policies) if config.is_multi_agent else [DEFAULT_MODULE_ID]
    if isinstance(spec, MultiRLModuleSpec):
        subs = {m: s for m, s in spec.rl_module_specs.items() if not is_aux_module(m)}
        out: dict[str, tuple] = {"": (spec.multi_rl_module_class,)}
    else:
        subs = {pid: spec or RLModuleSpec() for pid in pids}
        out = {"": (MultiRLModule,)}
    for mid, sub in subs.items():
        out[mid] = (
            sub.module_class or getattr(default, "module_class", None),
            sub.catalog_class,
            sub.model_config,
            sub.observation_space,
            sub.action_space,
            sub.inference_only,
            sub.learner_only,
        )
    return out
