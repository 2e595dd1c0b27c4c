"""Typed port values as people write and read them: maps with field names.

How it works: on the wire a typed value is the array of its fields (sdrpeer.sdk.typed). `to_wire`
turns a map of field names (what `sdrpeer port inject` takes as JSON or YAML) into that array,
checking every field against the type (unknown or missing field, wrong kind of value: a
`PortToolError` naming the field, e.g. `value.x: expected a float, got 'a'`); a field left out
takes the dataclass's default. A `bytes` field takes a base64 string. `to_fields` is the way
back, for `sdrpeer port print`: the array as a map (nested messages as nested maps).
"""

from __future__ import annotations

import base64
import binascii
import dataclasses
import typing
from collections.abc import Mapping
from typing import Any

from sdrpeer.errors import PortToolError
from sdrpeer.sdk.typed import MessageType, message_type

_MISSING = object()


def _nested(info: MessageType) -> dict[str, MessageType]:
    hints = typing.get_type_hints(info.cls)
    out: dict[str, MessageType] = {}
    for name, _ in info.fields:
        sub = message_type(hints[name])
        if sub is not None:
            out[name] = sub
    return out


def _defaults(info: MessageType) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for f in dataclasses.fields(info.cls):
        if f.default is not dataclasses.MISSING:
            out[f.name] = f.default
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = f.default_factory()
    return out


def _scalar(kind: str, value: Any, where: str) -> Any:
    if kind == "any":
        return value
    if kind == "float" and isinstance(value, int | float) and not isinstance(value, bool):
        return float(value)
    if kind == "int" and isinstance(value, int) and not isinstance(value, bool):
        return value
    if kind == "bool" and isinstance(value, bool):
        return value
    if kind == "str" and isinstance(value, str):
        return value
    if kind == "bytes":
        if isinstance(value, bytes):
            return value
        if isinstance(value, str):
            try:
                return base64.b64decode(value, validate=True)
            except binascii.Error:
                raise PortToolError(f"{where}: expected base64 text, got {value!r:.40}") from None
        raise PortToolError(f"{where}: expected bytes as a base64 string, got {value!r:.40}")
    if kind.startswith("list[") and isinstance(value, list):
        inner = kind[5:-1]
        return [_scalar(inner, v, f"{where}[{i}]") for i, v in enumerate(value)]
    article = "an" if kind[0] in "aeiou" else "a"
    raise PortToolError(f"{where}: expected {article} {kind}, got {value!r:.40}")


def to_wire(info: MessageType, doc: Any, where: str = "value") -> list[Any]:
    """A map of field names -> the wire array of `info`'s type, every field checked."""
    if not isinstance(doc, Mapping):
        names = ", ".join(n for n, _ in info.fields)
        raise PortToolError(f"{where}: a {info.type_id} is a map of its fields ({names})")
    known = [n for n, _ in info.fields]
    for key in doc:
        if key not in known:
            raise PortToolError(
                f"{where}.{key}: {info.type_id} has no such field (fields: {', '.join(known)})"
            )
    nested = _nested(info)
    defaults = _defaults(info)
    wire: list[Any] = []
    for name, kind in info.fields:
        value = doc.get(name, _MISSING)
        if value is _MISSING:
            if name not in defaults:
                raise PortToolError(f"{where}.{name}: missing (a {info.type_id} needs it)")
            value = defaults[name]
            sub = nested.get(name)
            wire.append(sub.flat(value) if sub is not None else value)
            continue
        sub = nested.get(name)
        if sub is not None:
            wire.append(to_wire(sub, value, f"{where}.{name}"))
        else:
            wire.append(_scalar(kind, value, f"{where}.{name}"))
    return wire


def to_fields(info: MessageType, wire: Any) -> Any:
    """The wire array of `info`'s type as a map of field names (anything else as it is)."""
    if not isinstance(wire, list | tuple) or len(wire) != info.arity:
        return wire
    nested = _nested(info)
    out: dict[str, Any] = {}
    for (name, _), value in zip(info.fields, wire, strict=True):
        sub = nested.get(name)
        out[name] = to_fields(sub, value) if sub is not None else value
    return out


def schema_fields(info: MessageType | None) -> list[list[str]]:
    """[[field, type], ...] of a type (what a recording's schema carries); [] when untyped."""
    return [] if info is None else [[n, t] for n, t in info.fields]
