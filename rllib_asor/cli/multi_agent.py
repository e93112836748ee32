"""The YAML `multi_agent:` block: policies and the policy mapping, e.g. one shared policy.

```yaml
config:
  multi_agent:
    policies: [shared]              # policy ids (spaces are inferred from the env)
    policy_mapping_fn: shared       # a policy id (every agent acts with it) or 'pkg.module:fn'
    policies_to_train: [shared]     # optional; default: all
```

becomes `config.multi_agent(policies={...}, policy_mapping_fn=..., policies_to_train=...)`.
A mapping to one policy id is a `MapEveryAgentTo` instance (picklable by reference, so
checkpoints and Ray workers can load it). `grid_search` is not allowed inside the block.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

KEYS = ("policies", "policy_mapping_fn", "policies_to_train")
"""Allowed keys of the block."""


@dataclass(frozen=True)
class MapEveryAgentTo:
    """Policy mapping function: every agent acts with `policy_id`."""

    policy_id: str

    def __call__(self, agent_id: Any, *args: Any, **kwargs: Any) -> str:
        return self.policy_id


def _ids(value: Any, key: str) -> list[str]:
    if (
        isinstance(value, str)
        or not isinstance(value, list | tuple)
        or not value
        or not all(isinstance(v, str) and v for v in value)
    ):
        raise ValueError(
            f"multi_agent.{key}={value!r} is invalid: allowed a non-empty list of policy ids "
            "(strings), e.g. [shared]"
        )
    if len(set(value)) != len(value):
        raise ValueError(f"multi_agent.{key}={value!r} is invalid: policy ids must be unique")
    return list(value)


def _mapping_fn(value: Any, policies: list[str]) -> Callable[..., str]:
    allowed = f"one of the policy ids {policies} or a function path 'package.module:function'"
    if not isinstance(value, str) or not value:
        raise ValueError(f"multi_agent.policy_mapping_fn={value!r} is invalid: allowed {allowed}")
    if value in policies:
        return MapEveryAgentTo(value)
    if ":" not in value:
        raise ValueError(
            f"multi_agent.policy_mapping_fn={value!r} is not a policy id: allowed {allowed}"
        )
    module_name, _, attr = value.partition(":")
    try:
        fn = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as e:
        raise ValueError(
            f"multi_agent.policy_mapping_fn={value!r} cannot be imported ({e}): allowed {allowed}"
        ) from None
    if not callable(fn):
        raise ValueError(
            f"multi_agent.policy_mapping_fn={value!r} is not callable: allowed {allowed}"
        )
    return fn


def parse(block: Any) -> dict[str, Any]:
    """Keyword arguments of `AlgorithmConfig.multi_agent` for the block; ValueError if bad."""
    if not isinstance(block, dict):
        raise ValueError(
            f"multi_agent={block!r} is invalid: allowed a mapping with keys {', '.join(KEYS)}"
        )
    unknown = sorted(set(block) - set(KEYS))
    if unknown:
        raise ValueError(f"multi_agent.{unknown[0]} is unknown: allowed {', '.join(KEYS)}")
    for key in ("policies", "policy_mapping_fn"):
        if key not in block:
            raise ValueError(f"multi_agent.{key} is missing: allowed keys {', '.join(KEYS)}")
    policies = _ids(block["policies"], "policies")
    out: dict[str, Any] = {
        "policies": set(policies),
        "policy_mapping_fn": _mapping_fn(block["policy_mapping_fn"], policies),
    }
    if block.get("policies_to_train") is not None:
        to_train = _ids(block["policies_to_train"], "policies_to_train")
        extra = sorted(set(to_train) - set(policies))
        if extra:
            raise ValueError(
                f"multi_agent.policies_to_train={to_train!r} is invalid: {extra[0]!r} is not in "
                f"policies {policies}"
            )
        out["policies_to_train"] = to_train
    return out
