"""`Settings`: the pydantic base our settings blocks are declared with (`AsorConfig`, ESCP's
and MAPLE's settings).

A block is declared once, as typed fields with attribute docstrings: pydantic validates it
(strict types, finite numbers, unknown keys refused), the docstrings are the fields'
descriptions, and `model_json_schema()` is its JSON Schema. Each field's type carries an
`Allowed` text, so a bad value is refused in one line naming the key, the value and what is
allowed: `asor.rho_value=1.5 is invalid: allowed a number in (0, 1]`.
"""

from __future__ import annotations

import difflib
import typing
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, Literal, Self

from pydantic import BaseModel, ConfigDict, Field, ValidationError


@dataclass(frozen=True)
class Allowed:
    """What a field takes, in words, for its error message (`Annotated` metadata):
    `Annotated[float, Field(gt=0), Allowed("a number > 0")]`."""

    text: str


def one_of(choices: tuple[str, ...]) -> Any:
    """A string field taking one of `choices` (a Literal), refused as "a | b | c"."""
    return Annotated[Literal[choices], Allowed(" | ".join(choices))]


class Settings(BaseModel):
    """Base of a settings block; `block` names it in messages (`asor`, `escp`, `maple`)."""

    model_config = ConfigDict(
        strict=True, allow_inf_nan=False, extra="forbid", use_attribute_docstrings=True
    )
    block: ClassVar[str] = "settings"
    label: ClassVar[str] = "a"
    """`escp.windw is not <label> setting`."""
    bad_value: ClassVar[str] = "{block}.{key}={value!r} is invalid: allowed {allowed}"
    """The one line for a bad value."""

    def __init__(self, /, **data: Any) -> None:
        try:
            super().__init__(**data)
        except ValidationError as e:
            raise ValueError(type(self).one_line(e, data)) from None

    @classmethod
    def one_line(cls, error: ValidationError, data: dict[str, Any]) -> str:
        """The first problem of `error` in one line: unknown keys, or the bad key, its value
        and the field's `Allowed` text, or a cross-field check's own message."""
        problems = error.errors()
        unknown = [str(p["loc"][0]) for p in problems if p["type"] == "extra_forbidden"]
        if unknown:
            return cls.unknown_keys(unknown)
        first = problems[0]
        if not first["loc"]:  # a check across fields raised its own message
            return str(first.get("ctx", {}).get("error", first["msg"]))
        key = str(first["loc"][0])
        return cls.bad_value.format(
            block=cls.block, key=key, value=data.get(key), allowed=cls.allowed(key)
        )

    @classmethod
    def unknown_keys(cls, unknown: Sequence[str]) -> str:
        """`escp.windw is not an ESCP setting (did you mean ...?): allowed a, b, ...`."""
        names = list(cls.model_fields)
        key = unknown[0]
        close = difflib.get_close_matches(key, names, n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        return f"{cls.block}.{key} is not {cls.label} setting{hint}: allowed {', '.join(names)}"

    @classmethod
    def allowed(cls, key: str) -> str:
        """The `Allowed` text of field `key`."""
        return allowed_text(cls, key)

    def to_dict(self) -> dict[str, Any]:
        """Plain-dict form (what RLlib configs store and `from_dict` reads back)."""
        return self.model_dump(mode="json")


class BlockSettings(Settings):
    """An algorithm's own frozen settings block (`escp:`, `osi:`, `bco:`, ...), read by
    `from_dict`; `label` is "a BCO" / "an OSI"."""

    model_config = ConfigDict(frozen=True)
    bad_value: ClassVar[str] = "{block}.{key}={value!r} is not allowed; expected {allowed}"

    @classmethod
    def from_dict(cls, d: Mapping[str, Any] | Self | None) -> Self:
        """Settings from a dict (the YAML block); a non-mapping, unknown keys and bad values
        raise ValueError in one line."""
        if d is None:
            return cls()
        if isinstance(d, cls):
            return d
        if not isinstance(d, Mapping):
            name = cls.label.split(" ", 1)[-1]
            raise ValueError(
                f"{cls.block}={d!r} is not allowed; expected a mapping of {name} settings"
            )
        return cls(**d)


IntAtLeast0 = Annotated[int, Field(ge=0), Allowed("an int ≥ 0")]
IntAtLeast1 = Annotated[int, Field(ge=1), Allowed("an int ≥ 1")]
NonNegative = Annotated[float, Field(ge=0), Allowed("a number ≥ 0")]
Positive = Annotated[float, Field(gt=0), Allowed("a number > 0")]


def allowed_text(model: type[BaseModel], key: str) -> str:
    """The `Allowed` text of `model`'s field `key` (from its metadata or its annotation)."""
    info = model.model_fields[key]
    return _allowed_in([*info.metadata, info.annotation]) or str(info.annotation)


def _allowed_in(items: Sequence[Any]) -> str | None:
    for item in items:
        if isinstance(item, Allowed):
            return item.text
        found = _allowed_in([*getattr(item, "__metadata__", ()), *typing.get_args(item)])
        if found:
            return found
    return None


def field_docs(model: type[BaseModel]) -> dict[str, str]:
    """Each field's description (its attribute docstring) on one line of single spaces."""
    return {
        name: " ".join((info.description or "").split())
        for name, info in model.model_fields.items()
    }
