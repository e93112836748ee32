"""The one wall around Ray/RLlib internals: every private Ray name rllib_asor uses is here.

Tested against the Ray releases in `RAY_TESTED` (pyproject.toml admits exactly these,
`RAY_REQUIREMENT`; `make compat RAY=<release>` runs the compat and glue tests on one of them,
docs/testing.md). Callers use the small functions below and touch no
name starting with `_` that Ray defines. `PRIVATE_NAMES` lists each private name read
or written here, with what we use it for; `OVERRIDES` lists the private methods our subclasses
override (RLlib calls them; the overrides stay in their classes). `missing()` names the ones the
installed Ray lacks (tests/rllib/test_compat.py fails on them), so a Ray upgrade breaks here,
in one place, with one line. No module of the package still touches a private Ray name
directly (tests, `studies/` and `benchmarks/` still read e.g. `learner_group._learner`).

Where a public API does the job it is used instead: `Learner.module` / `.device`,
`MultiRLModule.items()`, `AlgorithmConfig.rl_module(model_config=...)`,
`Learner.filter_param_dict_for_optimizer`. `config.learner_class` and `config.rl_module_spec`
are not such stand-ins: they fill in RLlib's defaults, and we need what the user set.

It sits at the package's top, not in `rllib/`, because the layers below the glue use it too
(`algorithms/`, `evaluation/`, `data/`; tests/test_import_graph.py keeps `algorithms/` from
importing `rllib_asor.rllib`) as well as `registry/` and `cli/`; it imports nothing of ours, so
every layer may import it. `asor/` and `envs/` never do (no Ray there). Ray is imported lazily
inside each function: importing this module costs nothing.

`fast_rllib()` is the one place that replaces names inside RLlib's modules, each with a function
that gives RLlib's result faster (the `inspect` of its connector module, its per-step
`unbatch`); our Learners' module and the RLlib glue call it on import, so every process that
builds our Algorithms has it (docs/speed.md).
"""

from __future__ import annotations

import ast
import importlib
import inspect
import sys
import textwrap
import types
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

RAY_TESTED = ("2.58.0", "2.58.1", "2.59.0", "2.60.0")
"""The Ray releases this module is tested against, oldest first: every name below exists in
each of them under the same owner (no lookup here depends on the version)."""

RAY_REQUIREMENT = "ray[rllib,tune]>=2.58,<2.61"
"""pyproject.toml's Ray requirement: of the releases there are, it admits exactly `RAY_TESTED`."""

_CONFIG = "ray.rllib.algorithms.algorithm_config:AlgorithmConfig"
_LEARNER = "ray.rllib.core.learner.learner:Learner"
_TORCH_LEARNER = "ray.rllib.core.learner.torch.torch_learner:TorchLearner"


@dataclass(frozen=True)
class Private:
    """One private Ray name: `owner` is "module" or "module:Class"; `use` says why we need it."""

    owner: str
    name: str
    use: str

    def __str__(self) -> str:
        return f"{self.owner}.{self.name}"


PRIVATE_NAMES: tuple[Private, ...] = (
    Private(_CONFIG, "_learner_class", "the Learner class the user set (None: RLlib's default)"),
    Private(_CONFIG, "_rl_module_spec", "the module spec the user set, before defaults merge"),
    Private(_CONFIG, "_env_to_module_connector", "the user's env-to-module builder, to wrap it"),
    Private(_CONFIG, "_translate_special_keys", "a YAML config key -> the config's attribute"),
    Private(_LEARNER, "_learner_connector", "the Learner's connector pipeline, to insert pieces"),
    Private(
        "ray.rllib.algorithms.sac.torch.sac_torch_learner:SACTorchLearner",
        "_temp_losses",
        "per-optimizer losses that SAC/CQL's compute_gradients pops",
    ),
    Private(_LEARNER, "_weights_seq_no", "the weights' version, to log off-policyness once"),
    Private(
        "ray.rllib.core.learner.learner_group",
        "_get_backend_config",
        "the Learner group's torch backend factory, wrapped to use gloo on a shared GPU",
    ),
    Private(
        "ray.rllib.core.learner.learner_group:LearnerGroup",
        "_learner",
        "the driver's local Learner (None when Learners are remote actors)",
    ),
    Private(
        "ray.rllib.utils.checkpoints:Checkpointable",
        "_check_component",
        "whether get_state was asked for a component",
    ),
    Private(
        "ray.rllib.algorithms.sac.sac_catalog:SACCatalog",
        "_encoder_config",
        "the catalog's encoder config, which our concat-MLP Q encoder copies",
    ),
    Private(
        "ray.rllib.core.distribution.torch.torch_distribution:TorchSquashedGaussian",
        "_squash",
        "tanh and rescale to the bounds: the squashed Gaussian's deterministic action",
    ),
    Private("ray.tune.registry", "_global_registry", "whether/what Tune has under a name"),
    Private("ray._common.deprecation", "DEPRECATED_VALUE", "RLlib's marker of a retired key"),
    Private(
        "ray._private.ray_logging",
        "global_worker_stdstream_dispatcher",
        "the handlers of forwarded worker output, to filter harmless lines",
    ),
    Private(
        "ray._private.ray_logging:WorkerStandardStreamDispatcher",
        "_lock",
        "held while we swap the dispatcher's handlers",
    ),
)
"""Every private Ray name this module reads or writes, with what we use it for."""

OVERRIDES: tuple[Private, ...] = (
    Private(_LEARNER, "_update", "one minibatch's update: offline ASOR's piece, SAC/ESCP/MAPLE extras"),
    Private(_LEARNER, "_make_batch_if_necessary", "flat replay batches; no_grad connectors"),
    Private(_LEARNER, "_create_iterator_if_necessary", "the fast path's minibatches of its flat batches"),
    Private(_TORCH_LEARNER, "_compute_off_policyness", "the metric once per update"),
    Private(_CONFIG, "_model_config_auto_includes", "ESCP/MAPLE settings into model_config"),
    Private(
        "ray.rllib.algorithms.sac.sac_catalog:SACCatalog",
        "_build_qf_encoder_continuous",
        "concat-MLP Q encoder for flat observations",
    ),
    Private("ray.rllib.core.rl_module.rl_module:RLModule", "_forward", "RLModule's forward hook"),
    Private("ray.rllib.core.rl_module.rl_module:RLModule", "_forward_train", "training forward"),
    Private("ray.rllib.core.rl_module.rl_module:RLModule", "_forward_inference", "greedy forward"),
    Private(
        "ray.rllib.core.rl_module.rl_module:RLModule", "_forward_exploration", "sampling forward"
    ),
)
"""RLlib's private methods our subclasses override (RLlib calls them; they call `super()`).
Only a subclass calls them, on `self` or `super()`."""

TO_DICT_KEYS: dict[str, str] = {
    "model_config": "_model_config",
    "train_batch_size_per_learner": "_train_batch_size_per_learner",
    "env_to_module_connector": "_env_to_module_connector",
    "rl_module": "_rl_module_spec",
    "learner_class": "_learner_class",
}
"""Config key -> its key in `AlgorithmConfig.to_dict()` (the Tune param space), where RLlib
stores the setting under a private attribute name."""


# -- AlgorithmConfig ------------------------------------------------------------------------


def user_learner_class(config: Any) -> type | None:
    """The Learner class set on `config` (None: RLlib picks `get_default_learner_class()`;
    the public `config.learner_class` cannot tell the two apart)."""
    return config._learner_class


def user_rl_module_spec(config: Any) -> Any:
    """The module spec set on `config` (None if unset), not merged with the defaults (the
    public `config.rl_module_spec` merges and needs the env's spaces)."""
    return config._rl_module_spec


def user_env_to_module_connector(config: Any) -> Any:
    """The env-to-module connector builder set on `config` (None if unset)."""
    return config._env_to_module_connector


def config_attr_name(key: str) -> str:
    """The `AlgorithmConfig` attribute a config key (as written in YAML) sets."""
    from ray.rllib.algorithms.algorithm_config import AlgorithmConfig

    return AlgorithmConfig._translate_special_keys(key, warn_deprecated=False)


def deprecated_value() -> Any:
    """RLlib's marker value of a retired config key."""
    from ray._common.deprecation import DEPRECATED_VALUE

    return DEPRECATED_VALUE


# -- Learner ----------------------------------------------------------------------------------


def learner_connector(learner: Any) -> Any:
    """The Learner's connector pipeline (None with aggregator actors)."""
    return learner._learner_connector


def temp_losses(learner: Any) -> dict[tuple[str, str], Any]:
    """A SAC-family Learner's `(module_id, "<optimizer>_loss") -> loss` dict that its
    `compute_gradients` pops: where a loss per optimizer goes."""
    return learner._temp_losses


def weights_seq_no(learner: Any) -> int:
    """The version of the weights the Learner last got from the sampler."""
    return learner._weights_seq_no


def local_learner(learner_group: Any) -> Any:
    """The driver's own Learner, or None when the Learners are remote actors."""
    return getattr(learner_group, "_learner", None)


def backend_config_factory() -> Callable[[type], Any]:
    """RLlib's `learner_class -> TorchConfig` factory for its Learner groups."""
    from ray.rllib.core.learner import learner_group

    return learner_group._get_backend_config


def set_backend_config_factory(factory: Callable[[type], Any]) -> None:
    """Make RLlib's Learner groups built from now on use `factory` for their backend config."""
    from ray.rllib.core.learner import learner_group

    learner_group._get_backend_config = factory


# -- Checkpoints, catalogs, distributions --------------------------------------------------------


def wants_component(obj: Any, name: str, components: Any, not_components: Any) -> bool:
    """Whether `obj.get_state(components, not_components=...)` should include `name`."""
    return obj._check_component(name, components, not_components)


def catalog_encoder_config(catalog: Any) -> Any:
    """The encoder config an RLlib catalog derived from the model config."""
    return catalog._encoder_config


def squash(dist: Any, sample: Any) -> Any:
    """`TorchSquashedGaussian`: tanh of `sample`, rescaled and clipped to the bounds."""
    return dist._squash(sample)


# -- Tune registry, worker logs ------------------------------------------------------------------


def tune_registry_contains(category: str, name: str) -> bool:
    """Whether Tune's registry holds `name` under `category` (`ray.tune.registry` constants)."""
    from ray.tune.registry import _global_registry

    return _global_registry.contains(category, name)


def tune_registry_get(category: str, name: str) -> Any:
    """What Tune's registry holds under `category`/`name` (e.g. an env creator)."""
    from ray.tune.registry import _global_registry

    return _global_registry.get(category, name)


def edit_worker_output_handlers(edit: Callable[[list[Any]], list[Any]]) -> bool:
    """Replace the handlers of the worker output Ray forwards to the driver with
    `edit(handlers)` (a list of `(name, handler)`); False if this Ray has no such hook."""
    try:
        from ray._private.ray_logging import global_worker_stdstream_dispatcher as dispatcher
    except ImportError:
        return False
    with dispatcher._lock:
        dispatcher.handlers = edit(list(dispatcher.handlers))
    return True


def _stack_without_source(context: int = 1) -> list[inspect.FrameInfo]:
    """`inspect.stack()` without the source lines: the same frames, outermost last, each
    `FrameInfo` with `code_context=None` (no file is read)."""
    frame = sys._getframe(1)
    frames = []
    while frame is not None:
        code = frame.f_code
        frames.append(
            inspect.FrameInfo(frame, code.co_filename, frame.f_lineno, code.co_name, None, None)
        )
        frame = frame.f_back
    return frames


def fast_connector_init() -> None:
    """Make RLlib's `ConnectorV2.__init__` cheap, with the same result (idempotent).

    To record a connector's constructor arguments it takes its caller's frame as
    `inspect.stack()[1].frame`, and `inspect.stack()` reads the source lines of every frame
    on the stack: 30-60 ms per connector, about a fifth of building a small PPO Algorithm and
    more under a deep stack (docs/speed.md). Its module gets an `inspect` whose `stack`
    returns the same frames without reading any file; the caller's frame, all it uses, is the
    same object."""
    import ray.rllib.connectors.connector_v2 as connector_v2

    if getattr(connector_v2, "inspect", None) is not inspect:  # patched, or RLlib changed
        return
    shim = types.ModuleType("inspect", inspect.__doc__)
    shim.__dict__.update(inspect.__dict__)
    shim.stack = _stack_without_source
    connector_v2.inspect = shim


def _unbatch(batches_struct: Any) -> list[Any]:
    """RLlib's `space_utils.unbatch` (a batch's struct → one struct per row), without dm-tree's
    per-row `unflatten_as` where there is nothing to unflatten: a numpy array gives its rows, a
    plain dict of numpy arrays one dict per row (its keys in its order, as `unflatten_as`);
    anything else goes to RLlib's."""
    import numpy as np

    if type(batches_struct) is np.ndarray and batches_struct.ndim:
        return list(batches_struct)
    if (
        type(batches_struct) is dict
        and batches_struct
        and all(type(k) is str for k in batches_struct)
        and all(type(v) is np.ndarray and v.ndim for v in batches_struct.values())
    ):
        rows = len(batches_struct[min(batches_struct)])  # RLlib: the first leaf, keys sorted
        items = batches_struct.items()
        return [{k: v[i] for k, v in items} for i in range(rows)]
    from ray.rllib.utils.spaces.space_utils import unbatch

    return unbatch(batches_struct)


_UNBATCH_USERS = (
    ("ray.rllib.env.single_agent_env_runner", "unbatch"),
    ("ray.rllib.connectors.module_to_env.unbatch_to_individual_items", "unbatch_fn"),
)
"""The modules that call `space_utils.unbatch` on every env step, and their name for it."""


def fast_unbatch() -> None:
    """Make RLlib's per-env-step `unbatch` calls cheap, with the same result (idempotent).

    A single-agent env runner unbatches the env's observations and the actions, and the
    module-to-env pipeline every column of the module's output, once per env step; RLlib's
    `unbatch` runs dm-tree's `unflatten_as` once per row even on a plain array (about a tenth
    of a race runner's time under cProfile). Each caller's module gets `_unbatch` instead."""
    from ray.rllib.utils.spaces.space_utils import unbatch

    for module_name, name in _UNBATCH_USERS:
        module = importlib.import_module(module_name)
        if getattr(module, name, None) is unbatch:  # not yet replaced; RLlib's own function
            setattr(module, name, _unbatch)


def fast_rllib() -> None:
    """RLlib's same-result speed-ups for this process: `fast_connector_init`, `fast_unbatch`."""
    fast_connector_init()
    fast_unbatch()


# -- The check ---------------------------------------------------------------------------------


def _has(owner: str, name: str) -> bool:
    module_name, _, cls_name = owner.partition(":")
    try:
        module = importlib.import_module(module_name)
    except ImportError:
        return False
    if not cls_name:
        return hasattr(module, name)
    cls = getattr(module, cls_name, None)
    if cls is None:
        return False
    if hasattr(cls, name):
        return True
    return any(name in _self_attrs(k) for k in cls.__mro__ if k.__module__.startswith("ray."))


def _self_attrs(cls: type) -> set[str]:
    """Names a class's own source assigns as `self.<name>` (instance attributes)."""
    try:
        tree = ast.parse(textwrap.dedent(inspect.getsource(cls)))
    except (OSError, TypeError, SyntaxError):
        return set()
    return {
        n.attr
        for n in ast.walk(tree)
        if isinstance(n, ast.Attribute)
        and isinstance(n.ctx, ast.Store)
        and isinstance(n.value, ast.Name)
        and n.value.id == "self"
    }


def unsupported_ray(version: str) -> str | None:
    """None if Ray `version` is one of `RAY_TESTED`, else one line naming the tested ones."""
    if version in RAY_TESTED:
        return None
    return (
        f"Ray {version} is not one rllib-asor is tested with; tested: {', '.join(RAY_TESTED)} "
        f"({RAY_REQUIREMENT})"
    )


def missing() -> list[str]:
    """The names of `PRIVATE_NAMES`, `OVERRIDES` and `TO_DICT_KEYS` the installed Ray lacks."""
    from ray.rllib.algorithms.algorithm_config import AlgorithmConfig

    gone = [str(p) for p in PRIVATE_NAMES + OVERRIDES if not _has(p.owner, p.name)]
    keys = AlgorithmConfig().to_dict()
    return gone + [
        f"AlgorithmConfig.to_dict()[{k!r}]" for k in TO_DICT_KEYS.values() if k not in keys
    ]
