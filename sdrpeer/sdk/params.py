"""Typed component parameters declared on the class, changeable while the component runs.

How it works: `Param(type, default, ...)` is a descriptor. `Component.__init_subclass__` collects
the class's params (their attribute names become the param names); each instance keeps its values
in a plain dict (`_param_values`) that the descriptor reads, so `self.rate` is a dict lookup.
`Param.convert` turns a value from the CLI (`--param rate=10`, always strings) or from the
control channel (msgpack: ints, floats, bools, strings) into the declared type and checks
`choices`, `min` and `max`; anything else is a `ParamError` naming the param and expected type.
The runner (`ComponentRunner.set_params`) validates every value of a change before applying any,
then calls each changed param's `on_change` and the component's `on_params_changed(changed)`.
"""

from __future__ import annotations

import builtins
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Final, Generic, TypeVar, overload

from sdrpeer.sdk.errors import ParamError

__all__ = ["Param", "ParamInfo"]

T = TypeVar("T", int, float, str, bool)

_TRUE: Final = frozenset({"true", "yes", "on", "1"})
_FALSE: Final = frozenset({"false", "no", "off", "0"})


@dataclass(frozen=True, slots=True)
class ParamInfo:
    """What the host reports about one param (in `hello`) and `sdrpeer` shows to users."""

    name: str
    """The attribute name, used as the param's name everywhere."""
    type: str
    """`int`, `float`, `str` or `bool`."""
    default: Any
    """The declared default, already converted."""
    doc: str
    """One line for people."""
    choices: tuple[Any, ...] | None
    """The allowed values, or None for any value of the type."""
    min: float | None
    """Inclusive lower bound for numbers."""
    max: float | None
    """Inclusive upper bound for numbers."""

    def to_map(self) -> dict[str, Any]:
        """A msgpack/JSON-friendly map (no None-valued keys)."""
        out: dict[str, Any] = {"name": self.name, "type": self.type, "default": self.default}
        if self.doc:
            out["doc"] = self.doc
        if self.choices is not None:
            out["choices"] = list(self.choices)
        if self.min is not None:
            out["min"] = self.min
        if self.max is not None:
            out["max"] = self.max
        return out


class Param(Generic[T]):
    """A typed parameter declared as a class attribute of a Component."""

    __slots__ = ("choices", "default", "doc", "max", "min", "name", "on_change", "type")

    def __init__(
        self,
        type: type[T],
        default: T,
        doc: str = "",
        *,
        choices: Sequence[T] | None = None,
        min: float | None = None,
        max: float | None = None,
        on_change: str | Callable[[Any, T], Any] | None = None,
    ) -> None:
        if type not in (int, float, str, bool):
            raise TypeError(f"Param type must be int, float, str or bool, not {type!r}")
        self.type: builtins.type[T] = type
        self.name = "<unbound>"
        self.doc = doc
        self.min = min
        self.max = max
        self.choices: tuple[T, ...] | None = tuple(choices) if choices is not None else None
        self.on_change: str | Callable[[Any, T], Any] | None = on_change
        """A method name or a function `(component, new_value)`, sync or async, or None."""
        self.default: T = default
        """Converted and checked by `check()` when the Component class is created."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def check(self) -> None:
        """Convert and check the declared choices and default (ParamError if they do not fit)."""
        if self.choices is not None:
            self.choices = tuple(self._convert_type(c) for c in self.choices)
        self.default = self.convert(self.default)

    @overload
    def __get__(self, instance: None, owner: type | None = None) -> Param[T]: ...
    @overload
    def __get__(self, instance: object, owner: type | None = None) -> T: ...
    def __get__(self, instance: object | None, owner: type | None = None) -> Param[T] | T:
        if instance is None:
            return self
        value: T = instance._param_values[self.name]  # type: ignore[attr-defined]
        return value

    def __set__(self, instance: object, value: object) -> None:
        """Set from the component's own code: converted and checked, callbacks are not called."""
        instance._param_values[self.name] = self.convert(value)  # type: ignore[attr-defined]

    def info(self) -> ParamInfo:
        """This param's metadata."""
        return ParamInfo(
            self.name, self.type.__name__, self.default, self.doc, self.choices, self.min, self.max
        )

    def convert(self, value: object) -> T:
        """`value` as this param's type, checked against choices and bounds; else ParamError."""
        out = self._convert_type(value)
        if self.choices is not None and out not in self.choices:
            allowed = ", ".join(repr(c) for c in self.choices)
            raise ParamError(self.name, self._expected(), value, detail=f"{out!r} not in {allowed}")
        if isinstance(out, int | float) and not isinstance(out, bool):
            if self.min is not None and out < self.min:
                raise ParamError(
                    self.name, self._expected(), detail=f"{out!r} below min {self.min}"
                )
            if self.max is not None and out > self.max:
                raise ParamError(
                    self.name, self._expected(), detail=f"{out!r} above max {self.max}"
                )
        return out

    def _expected(self) -> str:
        return self.type.__name__

    def _convert_type(self, value: object) -> T:
        t = self.type
        result: object
        if t is bool:
            result = _to_bool(value)
        elif t is int:
            result = _to_int(value)
        elif t is float:
            result = _to_float(value)
        else:
            result = value if isinstance(value, str) else None
        if result is None:
            raise ParamError(self.name, self._expected(), value)
        return result  # type: ignore[return-value]


def _to_bool(value: object) -> bool | None:
    if isinstance(value, bool):
        return value
    if isinstance(value, int) and value in (0, 1):
        return bool(value)
    if isinstance(value, str):
        low = value.strip().lower()
        if low in _TRUE:
            return True
        if low in _FALSE:
            return False
    return None


def _to_int(value: object) -> int | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, int):
        return value
    if isinstance(value, float):
        return int(value) if value.is_integer() else None
    if isinstance(value, str):
        try:
            return int(value.strip())
        except ValueError:
            return None
    return None


def _to_float(value: object) -> float | None:
    if isinstance(value, bool):
        return None
    if isinstance(value, int | float):
        out = float(value)
    elif isinstance(value, str):
        try:
            out = float(value.strip())
        except ValueError:
            return None
    else:
        return None
    return out if math.isfinite(out) else None
