"""The control channel's codec: each message dataclass <-> its msgpack map (docs/protocol.md).

How it works: at import, every message class (messages.py) gets a schema, one entry per field:
its wire key, a check made from the field's annotation (`_CHECKS`), whether the field is
required (no default), left off when None (`omit`) and which values it may take (`choices`).
`to_map` writes `"t"`, then a command's id (commands only: the channel gives it), then the fields
in their declared order, so the bytes are exactly those the hand-built maps had. `decode_*` read a
map the framing (stream.py) delivered: unknown keys are ignored; a missing required field, a value
of the wrong type or outside its choices raises `ProtocolError` naming the message and the field.
Numbers meant as floats may arrive as integers (a foreign host) and become floats. Pure, and
light (msgpack and dataclasses only): the host imports it.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import MISSING, dataclass, fields
from typing import Any, Final, TypeVar

import msgpack

from sdrpeer.control.messages import (
    COMMANDS,
    REPORTS,
    Command,
    Conn,
    Part,
    Report,
)
from sdrpeer.errors import ProtocolError

__all__ = [
    "decode_command",
    "decode_part",
    "decode_report",
    "encode",
    "encode_all",
    "id_of",
    "to_map",
    "type_of",
]

Message = Command | Report | Part
"""Anything the channel carries."""
_M = TypeVar("_M")


class _Wrong(Exception):
    """A value is not what its field needs (carries what was expected)."""


Check = Callable[[Any], Any]
"""Returns the value as the field holds it, or raises _Wrong."""


def _int(v: Any) -> int:
    if type(v) is not int:
        raise _Wrong("an integer")
    return v


def _float(v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, int | float):
        raise _Wrong("a number")
    return float(v)


def _str(v: Any) -> str:
    if not isinstance(v, str):
        raise _Wrong("a string")
    return v


def _bool(v: Any) -> bool:
    if not isinstance(v, bool):
        raise _Wrong("a boolean")
    return v


def _bytes(v: Any) -> bytes:
    if not isinstance(v, bytes):
        raise _Wrong("bytes")
    return v


def _map_of(value: Check | None, what: str) -> Check:
    def check(v: Any) -> dict[str, Any]:
        if not isinstance(v, dict) or not all(isinstance(k, str) for k in v):
            raise _Wrong(what)
        if value is not None:
            try:
                for item in v.values():
                    value(item)
            except _Wrong:
                raise _Wrong(what) from None
        return v

    return check


def _str_list(v: Any) -> list[str]:
    if not isinstance(v, list) or not all(isinstance(s, str) for s in v):
        raise _Wrong("a list of strings")
    return v


def _str_tuple(v: Any) -> tuple[str, ...]:
    return tuple(_str_list(v))


def _counters(v: Any) -> dict[str, int]:
    if not isinstance(v, dict) or not all(
        isinstance(k, str) and type(n) is int for k, n in v.items()
    ):
        raise _Wrong("a map")
    return v


SERVICE_ROLES: Final = ("provides", "requires")


def _service(v: Any) -> dict[str, Any]:
    """A hello's service port map: role, interface id, method names."""
    what = 'a service map {"role": provides|requires, "interface": str, "methods": [str]}'
    if (
        not isinstance(v, dict)
        or set(v) != {"role", "interface", "methods"}
        or v["role"] not in SERVICE_ROLES
        or not isinstance(v["interface"], str)
        or not v["interface"]
    ):
        raise _Wrong(what)
    try:
        _str_list(v["methods"])
    except _Wrong:
        raise _Wrong(what) from None
    return v


def _optional(check: Check) -> Check:
    def optional(v: Any) -> Any:
        return None if v is None else check(v)

    return optional


def _conn(v: Any) -> Conn:
    if not isinstance(v, dict):
        raise _Wrong("a map")
    return _decode_fields(Conn, v, "conn.")


_CHECKS: Final[dict[str, Check]] = {
    "int": _int,
    "float": _float,
    "str": _str,
    "bool": _bool,
    "bytes": _bytes,
    "dict[str, Any]": _map_of(None, "a map"),
    "dict[str, str]": _map_of(_str, "a map of strings"),
    "dict[str, list[str]]": _map_of(_str_list, "a map of string lists"),
    "dict[str, dict[str, int]]": _map_of(_counters, "a map of counter maps"),
    "dict[str, int]": _counters,
    "dict[str, dict[str, Any]]": _map_of(_service, "a map of service maps"),
    "tuple[str, ...]": _str_tuple,
    "Conn": _conn,
}
"""A check for each field annotation the messages use (`X | None` is X or nil)."""


@dataclass(frozen=True, slots=True)
class _Field:
    name: str
    wire: str
    check: Check
    required: bool
    omit: bool
    choices: tuple[Any, ...] | None


def _check_for(annotation: str) -> Check:
    if annotation.endswith(" | None"):
        return _optional(_CHECKS[annotation.removesuffix(" | None")])
    return _CHECKS[annotation]


def _schema(cls: type) -> tuple[_Field, ...]:
    return tuple(
        _Field(
            name=f.name,
            wire=f.metadata.get("wire", f.name),
            check=_check_for(str(f.type)),
            required=f.default is MISSING and f.default_factory is MISSING,
            omit=bool(f.metadata.get("omit")),
            choices=f.metadata.get("choices"),
        )
        for f in fields(cls)
    )


_SCHEMAS: Final[dict[type, tuple[_Field, ...]]] = {
    cls: _schema(cls) for cls in (*COMMANDS, *REPORTS, Part, Conn)
}
_COMMAND_TYPES: Final[dict[str, type[Command]]] = {cls.T: cls for cls in COMMANDS}
_REPORT_TYPES: Final[dict[str, type[Report]]] = {cls.T: cls for cls in REPORTS}


def _short(value: Any) -> str:
    text = repr(value)
    return text if len(text) <= 60 else f"{text[:57]}..."


def _decode_fields(cls: type[_M], raw: Mapping[str, Any], where: str = "") -> _M:
    """`cls` from the map `raw`; ProtocolError naming the field (`where` prefixes its key)."""
    values: dict[str, Any] = {}
    for f in _SCHEMAS[cls]:
        if f.wire not in raw:
            if f.required:
                raise _Bad(f"no '{where}{f.wire}'")
            continue
        value = raw[f.wire]
        try:
            value = f.check(value)
        except _Wrong as exc:
            raise _Bad(f"'{where}{f.wire}' must be {exc}, got {_short(value)}") from None
        if f.choices is not None and value not in f.choices:
            raise _Bad(f"unknown {where}{f.wire} {_short(value)}")
        values[f.name] = value
    return cls(**values)


class _Bad(Exception):
    """A field is wrong (the text says which); decode_* add the message type."""


def _decode(cls: type[_M], t: str, raw: Mapping[str, Any]) -> _M:
    try:
        return _decode_fields(cls, raw)
    except _Bad as exc:
        raise ProtocolError(f"{t}: {exc}") from None


def decode_report(raw: Mapping[str, Any]) -> Report | Part | None:
    """The report (or part) in `raw` (a map with a str "t"); None for an unknown "t"."""
    t = raw["t"]
    if t == Part.T:
        return _decode(Part, t, raw)
    cls = _REPORT_TYPES.get(t)
    return None if cls is None else _decode(cls, t, raw)


def decode_command(raw: Mapping[str, Any]) -> Command:
    """The command in `raw` (its id aside: `id_of`); ProtocolError if unknown or malformed."""
    t = raw["t"]
    cls = _COMMAND_TYPES.get(t)
    if cls is None:
        raise ProtocolError(f"unknown command {t!r}")
    return _decode(cls, t, raw)


def decode_part(raw: Mapping[str, Any]) -> Part:
    """The `part` in `raw`; ProtocolError if `of` is not an integer or `data` not bytes."""
    return _decode(Part, Part.T, raw)


def type_of(raw: Mapping[str, Any]) -> str:
    """A map's `"t"` (the framing made sure it is a str)."""
    return str(raw["t"])


def id_of(raw: Mapping[str, Any]) -> int | None:
    """A command map's integer id; None when it has none (then it is no command)."""
    ident = raw.get("id")
    return ident if type(ident) is int else None


def _fields_map(msg: Any, out: dict[str, Any]) -> dict[str, Any]:
    for f in _SCHEMAS[type(msg)]:
        value = getattr(msg, f.name)
        if value is None and f.omit:
            continue
        out[f.wire] = _fields_map(value, {}) if isinstance(value, Conn) else value
    return out


def to_map(msg: Message, ident: int | None = None) -> dict[str, Any]:
    """`msg` as its wire map; a command needs `ident`, the id its reply will carry."""
    out: dict[str, Any] = {"t": msg.T}
    if isinstance(msg, COMMANDS):
        if ident is None:
            raise ValueError(f"{msg.T}: a command needs an id")
        out["id"] = ident
    return _fields_map(msg, out)


def encode(msg: Message, ident: int | None = None) -> bytes:
    """`msg` as msgpack (see `to_map`)."""
    return bytes(msgpack.packb(to_map(msg, ident), use_bin_type=True))


def encode_all(msgs: Sequence[Message]) -> bytes:
    """Several reports (or parts) as one write."""
    return b"".join(encode(m) for m in msgs)
