"""RLModule names a YAML can give (`module_class: race_net`), resolved to classes.

`get_module_class("race_net")` or `get_module_class("my.pkg.module:MyModule")` (a dotted path
with ``:`` or a last ``.`` before the class name) returns the class.
"""

from __future__ import annotations

import importlib

MODULES: dict[str, str] = {"race_net": "rllib_asor.race.net:RaceNetModule"}
"""Registered short names and the `module:Class` path each stands for."""


def get_module_class(name_or_dotted_path: str) -> type:
    """The RLModule class for a registered name or a `pkg.module:Class` / `pkg.module.Class` path.

    Raises ValueError naming the allowed names when the name is unknown or cannot be imported.
    """
    allowed = f"one of {sorted(MODULES)} or a dotted path 'package.module:Class'"
    if not isinstance(name_or_dotted_path, str) or not name_or_dotted_path:
        raise ValueError(f"module_class={name_or_dotted_path!r} is invalid: allowed {allowed}")
    path = MODULES.get(name_or_dotted_path, name_or_dotted_path)
    if ":" in path:
        module_name, _, attr = path.partition(":")
    elif "." in path:
        module_name, _, attr = path.rpartition(".")
    else:
        raise ValueError(f"module_class={name_or_dotted_path!r} is unknown: allowed {allowed}")
    try:
        cls = getattr(importlib.import_module(module_name), attr)
    except (ImportError, AttributeError) as e:
        raise ValueError(
            f"module_class={name_or_dotted_path!r} cannot be imported ({e}): allowed {allowed}"
        ) from e
    if not isinstance(cls, type):
        raise ValueError(f"module_class={name_or_dotted_path!r} is not a class: allowed {allowed}")
    return cls
