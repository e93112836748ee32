"""`with_asor(config, **settings)`: switch ASOR on for an RLlib AlgorithmConfig.

What it wires in:
- the algorithm's ASOR Learner class (PPO: `AsorPPOTorchLearner`),
- per trained policy a `learner_only` discriminator and (modes `asor`/`count`) a proxy module
  in the MultiRLModule (`asor_disc.<policy>`, `asor_proxy.<policy>`),
- the validated settings in `learner_config_dict["asor"]` (pickled into every Learner and
  checkpoint),
- a callback that lifts the Learner's ASOR statistics to `asor/...` in the results,
- for SAC and CQL the fast off-policy path (`fast_off_policy`, rllib_asor/algorithms/sac/fast.py:
  concat-MLP critics, flat replay buffer, batch built without the connector walk), unless
  `learner_config_dict["fast_off_policy"]` is False.
"""

from __future__ import annotations

import copy
import dataclasses
from typing import Any

from ray.rllib.algorithms.algorithm_config import AlgorithmConfig
from ray.rllib.core import DEFAULT_MODULE_ID
from ray.rllib.core.rl_module.multi_rl_module import MultiRLModuleSpec
from ray.rllib.core.rl_module.rl_module import RLModuleSpec

from rllib_asor import ray_compat as compat
from rllib_asor.algorithms.common.callbacks import add_callbacks
from rllib_asor.algorithms.sac.fast import FAST_KEY, fast_off_policy
from rllib_asor.asor.config import ALGORITHMS, AsorConfig
from rllib_asor.registry.env_names import register_env
from rllib_asor.rllib.callbacks import AsorMetricsCallback
from rllib_asor.rllib.escp_asor import AsorESCPTorchLearner
from rllib_asor.rllib.learners import (
    AsorCQLTorchLearner,
    AsorPPOTorchLearner,
    AsorSACTorchLearner,
    disc_module_id,
    is_aux_module,
    proxy_module_id,
)
from rllib_asor.rllib.maple_asor import AsorMapleTorchLearner
from rllib_asor.rllib.modules import AsorDiscriminatorModule, AsorProxyModule

SUPPORTED = {
    "PPO": AsorPPOTorchLearner,
    "SAC": AsorSACTorchLearner,
    "CQL": AsorCQLTorchLearner,
    "MAPLE": AsorMapleTorchLearner,  # MOPO too (a MAPLE subclass)
    "ESCP": AsorESCPTorchLearner,  # ESCP+ASOR, the paper's Algorithm 1
}
assert tuple(sorted(SUPPORTED)) == ALGORITHMS, "one list of supported algorithms (asor.config)"


class AsorMultiRLModuleSpec(MultiRLModuleSpec):
    """A MultiRLModuleSpec whose ASOR modules inherit their policy's spaces at build time.

    RLlib fills missing spaces only for policies; an auxiliary module `asor_disc.<pid>` takes
    the observation/action space of `<pid>`.
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
    learner_class = SUPPORTED.get(algo)
    if learner_class is None:
        raise ValueError(
            f"ASOR does not support algorithm {algo!r}: supported {', '.join(sorted(SUPPORTED))}"
        )
    if not config.enable_rl_module_and_learner:
        raise ValueError("ASOR needs RLlib's new API stack (enable_rl_module_and_learner=True)")
    if config.framework_str != "torch":
        raise ValueError(f"ASOR needs framework='torch', got {config.framework_str!r}")

    config = config.copy(copy_frozen=False)
    if isinstance(config.env, str):
        register_env(config.env)  # env runners (other processes, nodes) can then build it
    if algo in ("SAC", "CQL") and _wants_fast_path(config, asor):
        config = fast_off_policy(config)
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


def _algorithm_name(config: AlgorithmConfig) -> str:
    """ "PPO", "SAC", ... for the config's algorithm or a subclass of one (`OverlappedPPO`)."""
    cls = config.algo_class
    if cls is None:
        return type(config).__name__
    return next((c.__name__ for c in cls.__mro__ if c.__name__ in SUPPORTED), cls.__name__)


def _wants_fast_path(config: AlgorithmConfig, asor: AsorConfig) -> bool:
    """SAC/CQL get the fast off-policy path (rllib_asor/algorithms/sac/fast.py) unless the config
    opts out (`learner_config_dict["fast_off_policy"] = False`) or the proxy needs per-step
    infos, which the flat replay buffer does not keep (`rnd_per_dynamics`)."""
    if (config.learner_config_dict or {}).get(FAST_KEY) is False:
        return False
    return not (asor.needs_proxy and asor.proxy == "rnd_per_dynamics")


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
        specs[disc_module_id(pid)] = RLModuleSpec(
            module_class=AsorDiscriminatorModule,
            learner_only=True,
            model_config=dict(model_config),
            **spaces,
        )
        if asor.needs_proxy:
            specs[proxy_module_id(pid)] = RLModuleSpec(
                module_class=AsorProxyModule,
                learner_only=True,
                model_config=dict(model_config),
                **spaces,
            )
    return AsorMultiRLModuleSpec(**{**keep, "rl_module_specs": specs})
