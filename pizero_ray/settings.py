"""Settings declared once: a dataclass field carries its default, flag, help and allowed values.

``setting(...)`` is ``dataclasses.field`` with the rest in the field's
metadata. The command line is generated from ``declared(cls)`` (cli/arguments),
the options check their values against it, and tests/cli/test_reference.py
holds docs/options.md to it. Pure Python: no JAX, no Ray.
"""

from __future__ import annotations

import dataclasses
import math
import typing
from dataclasses import dataclass
from typing import Any, Callable

_KEY = "pizero_ray.setting"


@dataclass(frozen=True)
class Setting:
    """One declared setting: a dataclass field and how the command line sets it."""

    name: str  # the field (and the argparse dest)
    flag: str | None  # e.g. "--lr"; None: not on the command line
    help: str
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None  # allowed values (per item for a tuple)
    minimum: int | float | None  # the smallest allowed number
    metavar: str | None
    default: Any  # dataclasses.MISSING for a required field
    type: Any  # the field's annotation, resolved

    @property
    def allowed(self) -> tuple[str, ...] | None:
        """The allowed values (a callable is asked now: the environment names load lazily)."""
        return self.choices() if callable(self.choices) else self.choices

    @property
    def has_default(self) -> bool:
        return self.default is not dataclasses.MISSING


def setting(
    default: Any = dataclasses.MISSING,
    *,
    flag: str | None = None,
    help: str = "",
    choices: tuple[str, ...] | Callable[[], tuple[str, ...]] | None = None,
    minimum: int | float | None = None,
    metavar: str | None = None,
) -> Any:
    """A dataclass field whose default, flag, help, choices and minimum are declared here, once."""
    metadata = {_KEY: {"flag": flag, "help": help, "choices": choices, "minimum": minimum, "metavar": metavar}}
    return dataclasses.field(default=default, metadata=metadata)


def declared(cls: type) -> tuple[Setting, ...]:
    """The settings of a dataclass in field order; a field holding a dataclass contributes that one's settings."""
    hints = typing.get_type_hints(cls)
    found: list[Setting] = []
    for field in dataclasses.fields(cls):
        kind = hints[field.name]
        if dataclasses.is_dataclass(kind):
            found.extend(declared(kind))
        elif _KEY in field.metadata:
            found.append(Setting(name=field.name, default=field.default, type=kind, **field.metadata[_KEY]))
    return tuple(found)


def lookup(cls: type, name: str) -> Setting:
    """The declared setting ``name`` of ``cls`` (or of a dataclass it holds)."""
    (found,) = [s for s in declared(cls) if s.name == name]
    return found


def check_minimums(instance: Any, error: type[Exception]) -> None:
    """Raises ``error`` naming the first declared setting of ``instance`` that is below its minimum, or the
    first number that is not finite (NaN and infinity pass every comparison check, or fail none)."""
    check_finite(instance, error)
    for s in declared(type(instance)):
        value = getattr(instance, s.name, None)
        if s.minimum is not None and value is not None and value < s.minimum:
            raise error(f"{s.flag or s.name} must be at least {s.minimum}, got {value!r}")


def check_finite(instance: Any, error: type[Exception]) -> None:
    """Raises ``error`` naming the first float field of a dataclass ``instance`` that is NaN or infinite."""
    for field in dataclasses.fields(instance):
        value = getattr(instance, field.name)
        if isinstance(value, float) and not math.isfinite(value):
            flag = field.metadata.get(_KEY, {}).get("flag")
            raise error(f"{flag or field.name} must be a finite number, got {value!r}")
