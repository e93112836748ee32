"""Config values checked against the types RLlib 2.60 declares for them.

The types come from the signatures of the AlgorithmConfig setters (`training`, `env_runners`,
`evaluation`, ... of the algorithm's config class and its bases: every parameter whose default
is `NotProvided` is a setting), else from the type of the setting's default. A value of the wrong
type is refused in one line naming the key, the value and the type allowed. A number that YAML
read as text (`lr: 5e-5`, YAML 1.1 needs `5.0e-5`) is read as the number, with a warning.
"""

from __future__ import annotations

import functools
import inspect
import re
import types
import typing
from typing import Any

from rllib_asor.cli.errors import Problems, UsageError

_NUMBER = re.compile(r"^[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$")
_FRACTIONAL = re.compile(r"^num_(cpus|gpus)(_|$)")
"""CPU/GPU counts: Ray takes fractions where RLlib's annotations say int (0.5 CPU per runner)."""
_UNKNOWN = object()


@functools.lru_cache(maxsize=32)
def declared_types(config_class: type) -> dict[str, Any]:
    """Setting name -> annotation, from the setter signatures of `config_class` and its bases
    (the most derived class's annotation wins)."""
    from ray.rllib.utils.from_config import NotProvided

    out: dict[str, Any] = {}
    for cls in config_class.__mro__:
        for name, fn in vars(cls).items():
            if name.startswith("_") or not inspect.isfunction(fn):
                continue
            try:
                params = inspect.signature(fn).parameters.values()
            except (TypeError, ValueError):
                continue
            for p in params:
                if p.default is NotProvided and p.annotation is not inspect.Parameter.empty:
                    out.setdefault(p.name, p.annotation)
    return out


def _accepts(annotation: Any, value: Any) -> bool:
    """True if `value` fits `annotation` (containers: the container type only; classes,
    callables and other objects: anything)."""
    if annotation is Any or annotation is inspect.Parameter.empty or isinstance(annotation, str):
        return True
    if annotation is None or annotation is type(None):
        return value is None
    origin = typing.get_origin(annotation)
    if origin is typing.Union or origin is types.UnionType:
        return any(_accepts(a, value) for a in typing.get_args(annotation))
    if origin is typing.Literal:
        return value in typing.get_args(annotation)
    if annotation is bool:
        return isinstance(value, bool)
    if annotation is int:
        return isinstance(value, int) and not isinstance(value, bool)
    if annotation is float:
        return isinstance(value, int | float) and not isinstance(value, bool)
    if annotation is str:
        return isinstance(value, str)
    target = origin or annotation
    if target in (list, tuple, typing.List, typing.Tuple):  # noqa: UP006
        return isinstance(value, list | tuple)
    if target in (dict, typing.Dict):  # noqa: UP006
        return isinstance(value, dict)
    import collections.abc as abc

    if target in (abc.Sequence, abc.Collection):
        return isinstance(value, list | tuple)
    if target is abc.Mapping:
        return isinstance(value, dict)
    return True  # classes, callables, spaces, envs: a string path or an object may do


def describe(annotation: Any) -> str:
    """The annotation in words: 'an integer or null', 'a number', ..."""
    names = {
        bool: "true or false",
        int: "an integer",
        float: "a number",
        str: "a string",
        type(None): "null",
    }
    origin = typing.get_origin(annotation)
    if origin is typing.Union or origin is types.UnionType:
        parts = list(dict.fromkeys(describe(a) for a in typing.get_args(annotation)))
        return " or ".join(parts)
    if origin is typing.Literal:
        return " | ".join(repr(a) for a in typing.get_args(annotation))
    if annotation in names:
        return names[annotation]
    target = origin or annotation
    if target in (list, tuple, typing.List, typing.Tuple):  # noqa: UP006
        return "a list"
    if target in (dict, typing.Dict):  # noqa: UP006
        return "a mapping"
    return getattr(annotation, "__name__", str(annotation))


def _from_default(default: Any) -> Any:
    """An annotation from a setting's default value (numbers and booleans only), else unknown."""
    if isinstance(default, bool):
        return bool | None
    if isinstance(default, int):
        return int | None
    if isinstance(default, float):
        return float | None
    return _UNKNOWN


def _as_number(value: Any, annotation: Any) -> Any:
    """`value` as a number where it is a number in text that the annotation refuses as text
    but takes as a number; else `value`."""
    if (
        not isinstance(value, str)
        or not _NUMBER.match(value.strip())
        or _accepts(annotation, value)
    ):
        return value
    number = float(value)
    if number.is_integer() and _accepts(annotation, int(number)):
        return int(number)
    return number if _accepts(annotation, number) else value


def check_value(key: str, attr: str, value: Any, default_cfg: Any) -> tuple[Any, str | None]:
    """(the value, maybe read as a number; a warning or None); ValueError naming key, value
    and the type allowed if RLlib declares another type."""
    declared = declared_types(type(default_cfg))
    annotation = declared.get(key, declared.get(attr, _UNKNOWN))
    if annotation is _UNKNOWN:
        annotation = _from_default(getattr(default_cfg, attr, None))
    if _FRACTIONAL.match(attr) and annotation is not _UNKNOWN:
        annotation = annotation | float
    if annotation is _UNKNOWN or _accepts(annotation, value):
        return value, None
    number = _as_number(value, annotation)
    if number is not value:
        return number, f"{value!r} read as the number {number!r} (YAML 1.1 reads it as text)"
    raise ValueError(f"{value!r} is invalid: allowed {describe(annotation)}")


def check_config_values(exp: Any, default_cfg: Any, attr_name: Any) -> None:
    """Check every top-level config value (each grid candidate too) of `exp` in place; a
    number written as text is replaced by the number with a warning. UsageError otherwise
    (naming every key of a wrong type)."""
    from rllib_asor.cli import grid

    problems = Problems()
    for key, value in list(exp.config.items()):
        attr = attr_name(key)
        is_grid = grid.is_grid(value)
        candidates = value["grid_search"] if is_grid else [value]
        if not isinstance(candidates, list):
            continue
        fixed = []
        for candidate in candidates:
            try:
                new, note = check_value(key, attr, candidate, default_cfg)
            except ValueError as e:
                problems.add(UsageError(str(e), source=exp.source, key=f"{exp.name}.config.{key}"))
                break  # one line per key
            if note:
                exp.warnings.append(f"{exp.source}: {exp.name}.config.{key}: {note}")
            fixed.append(new)
        else:
            exp.config[key] = {"grid_search": fixed} if is_grid else fixed[0]
    problems.raise_any()
