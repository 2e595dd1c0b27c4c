"""Typed port messages: a dataclass declared with `@message("pkg/Name")` is a port's type.

How it works: `message(name)` reads the dataclass's fields once and builds three things:
- a *type id*, `name#digest`, the digest (8 hex digits of BLAKE2b) taken over the field names and
  types in order, so two programs that both say `mylab/Detection` but lay it out differently are
  told apart. It goes in the data stream's hello and in `sdrpeer system check`: two typed ends
  whose ids differ are refused (docs/protocol.md).
- an *encoder*: the value as a tuple of its fields in order (nested messages as nested tuples),
  which msgpack writes as an array: no field names on the wire. A message whose last field is
  `bytes` may carry a big blob (an image): the OutPort hands it to the data plane as a
  `WireBlob`, the fields before it packed once and the blob itself written without a copy.
- a *decoder*: an array back into the dataclass (`NoData`-free: a value of the wrong shape is a
  `PortTypeError` naming the port and the type).

Field types: `float`, `int`, `bool`, `str`, `bytes`, `list[float]`, `list[int]`, `list[str]`,
another message type, or `Any` (any msgpack value). Standard robot types with timestamps are in
sdrpeer.sdk.robot_types.
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Callable
from operator import attrgetter
from typing import Any, Final, TypeVar

import msgpack

from sdrpeer.sdk.errors import PortError

try:  # the C module itself: `hashlib` would load OpenSSL into every host (sdrpeer.host.lean)
    from _blake2 import blake2b
except ImportError:  # pragma: no cover - an interpreter without it
    from hashlib import blake2b

__all__ = [
    "MessageType",
    "PortTypeError",
    "WireBlob",
    "message",
    "message_type",
    "port_message",
    "type_id_of",
]

T = TypeVar("T")

_SCALARS: Final = {float: "float", int: "int", bool: "bool", str: "str", bytes: "bytes"}
_LISTS: Final = {float: "list[float]", int: "list[int]", str: "list[str]"}
BLOB_MIN: Final = 64 * 1024
"""A trailing bytes field at least this long travels as a `WireBlob` (the data plane's `BIG`)."""


class PortTypeError(PortError):
    """A value does not fit a typed port (written, or received from an untyped sender)."""


@dataclasses.dataclass(frozen=True, slots=True)
class WireBlob:
    """A typed value ready for the wire: `prefix` (the msgpack array header, every field before
    the blob and the blob's bin header) then `data`, written without copying it."""

    prefix: bytes
    data: bytes

    def __len__(self) -> int:
        return len(self.prefix) + len(self.data)


@dataclasses.dataclass(frozen=True, slots=True)
class MessageType:
    """What `message` learned about one dataclass."""

    cls: type
    name: str
    type_id: str
    fields: tuple[tuple[str, str], ...]
    """(field name, type name) in order."""
    encode: Callable[[Any], Any]
    """A value -> its wire form (a tuple, or a WireBlob)."""
    flat: Callable[[Any], tuple[Any, ...]]
    """A value -> a tuple (nested messages as tuples, never a WireBlob)."""
    decode: Callable[[Any], Any]
    """A wire form (a list) -> the dataclass."""
    build: Callable[..., Any] | None = None
    """The class itself when its wire array is its fields one to one (no nested message):
    `build(*wire)` makes the value from a list already known to hold `arity` elements (what
    an InPort checked on arrival), skipping `decode`'s checks. None: use `decode`."""

    @property
    def arity(self) -> int:
        """How many fields its wire array has."""
        return len(self.fields)


def _type_name(hint: Any, where: str) -> tuple[str, MessageType | None]:
    """A field's type name, and its message type when it is one."""
    if hint is Any:
        return "any", None
    if hint in _SCALARS:
        return _SCALARS[hint], None
    origin, args = typing.get_origin(hint), typing.get_args(hint)
    if origin is list and len(args) == 1 and args[0] in _LISTS:
        return _LISTS[args[0]], None
    nested = message_type(hint)
    if nested is not None:
        return nested.type_id, nested
    raise TypeError(
        f"{where}: a message field must be float, int, bool, str, bytes, list[float], "
        f"list[int], list[str], Any or another message type, not {hint!r}"
    )


def message(name: str) -> Callable[[type[T]], type[T]]:
    """Make a dataclass a port message type named `name` (e.g. `"mylab/Detection"`)."""
    if not name or len(name) > 100 or any(c.isspace() or c == "#" for c in name):
        raise ValueError(f"message name {name!r}: 1-100 characters, no spaces or '#'")

    def wrap(cls: type[T]) -> type[T]:
        if not dataclasses.is_dataclass(cls):
            raise TypeError(f"@message({name!r}) needs a dataclass, got {cls.__name__}")
        hints = typing.get_type_hints(cls)
        fields = [f.name for f in dataclasses.fields(cls)]
        if not fields:
            raise TypeError(f"@message({name!r}): {cls.__name__} has no fields")
        kinds: list[tuple[str, str]] = []
        nested: dict[int, MessageType] = {}
        for i, field in enumerate(fields):
            type_name, sub = _type_name(hints[field], f"{cls.__name__}.{field}")
            kinds.append((field, type_name))
            if sub is not None:
                nested[i] = sub
        layout = ";".join(f"{f}:{t}" for f, t in kinds)
        digest = blake2b(f"{name}({layout})".encode(), digest_size=4).hexdigest()
        type_id = f"{name}#{digest}"
        flat = _flat(fields, nested)
        blob = kinds[-1][1] == "bytes"
        info = MessageType(
            cls,
            name,
            type_id,
            tuple(kinds),
            _with_blob(flat) if blob else flat,
            flat,
            _decoder(cls, type_id, len(fields), nested),
            None if nested else cls,
        )
        cls.__sdr_message__ = info  # type: ignore[attr-defined]
        return cls

    return wrap


def _flat(fields: list[str], nested: dict[int, MessageType]) -> Callable[[Any], tuple[Any, ...]]:
    """A value -> the tuple of its fields (nested messages as tuples)."""
    get: Callable[[Any], Any]
    if len(fields) > 1:
        get = attrgetter(*fields)
    else:
        one = attrgetter(fields[0])

        def get(value: Any) -> tuple[Any, ...]:
            return (one(value),)

    if not nested:
        return get

    def flat_nested(value: Any) -> tuple[Any, ...]:
        parts = list(get(value))
        for i, sub in nested.items():
            parts[i] = sub.flat(parts[i])
        return tuple(parts)

    return flat_nested


def _with_blob(flat: Callable[[Any], tuple[Any, ...]]) -> Callable[[Any], Any]:
    """`flat`, except that a big trailing bytes field makes a WireBlob."""
    pack = msgpack.Packer().pack

    def encode_blob(value: Any) -> Any:
        parts = flat(value)
        data = parts[-1]
        if type(data) is not bytes or len(data) < BLOB_MIN:
            return parts
        n = len(parts)
        head = (b"\xdc" + n.to_bytes(2, "big")) if n > 15 else bytes([0x90 | n])
        rest = b"".join(pack(p) for p in parts[:-1])
        return WireBlob(head + rest + b"\xc6" + len(data).to_bytes(4, "big"), data)

    return encode_blob


def _decoder(
    cls: type, type_id: str, n: int, nested: dict[int, MessageType]
) -> Callable[[Any], Any]:
    def decode(wire: Any) -> Any:
        if type(wire) is not list or len(wire) != n:
            raise PortTypeError(f"expected a {type_id} ({n} fields), got {wire!r:.60}")
        if nested:  # into a copy: the received list may be decoded again (read() after get)
            wire = list(wire)
            for i, sub in nested.items():
                wire[i] = sub.decode(wire[i])
        try:
            return cls(*wire)
        except TypeError as e:
            raise PortTypeError(f"not a {type_id}: {e}") from None

    return decode


def message_type(cls: Any) -> MessageType | None:
    """The message type of a class declared with `@message`, else None."""
    info = getattr(cls, "__sdr_message__", None)
    return info if isinstance(info, MessageType) else None


def port_message(port_type: Any) -> MessageType | None:
    """The message type of a port declared with `type=` (None: untyped); TypeError when
    `port_type` is not a `@message` dataclass."""
    if port_type is None:
        return None
    info = message_type(port_type)
    if info is None:
        raise TypeError(f"a port type must be a @message dataclass, got {port_type!r}")
    return info


def type_id_of(port_type: Any) -> str | None:
    """The type id a port declared with `type=` carries (None: untyped)."""
    info = port_message(port_type)
    return None if info is None else info.type_id
