"""The data stream's codec (docs/protocol.md section 2): hello, reply, `[seq, value]` frames.

How it works: the stream is plain msgpack values, back to back. The sender writes one hello map,
the receiver answers one reply map, then the sender writes frames, each a two-element array
``[seq, value]``. Encoding a frame is a fixed header (array of 2, seq as a msgpack uint32 or
uint64) followed by the msgpack encoding of the value, so the sender packs a value once, when it
is offered, and numbers it only when it is written.

`FrameDecoder` wraps a `msgpack.Unpacker` with strict limits: the unpacker's buffer is capped
(a frame cannot grow it past `max_frame` plus one read), every frame's encoded size is checked
against `max_frame` (a frame still arriving too: the unpacker parses incrementally and `tell()`
counts what it consumed), and every frame must be ``[uint, value]`` (or, when its `refs` hook
is set, ``[seq, pos, length]``: a value in a shared-memory ring, which the hook resolves).
Whatever goes wrong raises `FrameError("oversized" | "malformed")`; no other exception escapes
the decoder.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final, cast

import msgpack

from sdrpeer.errors import FrameError

PROTOCOL_VERSION: Final = 1
DEFAULT_MAX_FRAME: Final = 16 * 1024 * 1024
HELLO_MAX: Final = 64 * 1024
"""The largest hello or reply map accepted (bytes)."""
FRAME_OVERHEAD: Final = 10
"""The most bytes a frame adds to its value's encoding (array header, uint64 seq)."""
READ_SLACK: Final = 1024 * 1024
"""Bytes the decoder accepts in one `feed` beyond `max_frame` (larger inputs are split)."""

_U32: Final = struct.Struct(">BBI").pack
_U64: Final = struct.Struct(">BBQ").pack


def _packb(value: object) -> bytes:
    return cast(bytes, msgpack.packb(value))


@dataclass(frozen=True, slots=True)
class Hello:
    """The sender's first message on a data connection."""

    conn: str
    """The connection id (chosen by whoever asked for the connection)."""
    in_port: str
    """The name of the receiving InPort."""
    from_: str
    """The sending `instance.port`."""
    policy: dict[str, Any]
    """The connection's own connector policy map (the keys it sets): the receiving InPort applies
    them over its declared policy to this connection's frames."""
    version: int = PROTOCOL_VERSION
    """The data stream protocol version."""
    shm: object = None
    """A shared-memory ring the sender offers (sdrpeer.dataplane.shm), or None."""
    ack: AckOffer | None = None
    """The sender keeps frames until they are acknowledged (sdrpeer.dataplane.retention)."""
    auth: bytes | None = None
    """The sender's nonce when it authenticates (sdrpeer.dataplane.auth)."""
    enc: bool = False
    """The sender asks for an encrypted stream (sdrpeer.dataplane.seal; with `auth`, on TCP)."""
    type: str | None = None
    """The sending port's message type id (sdrpeer.sdk.typed), None when it sends any value."""
    svc: str | None = None
    """A service binding (sdrpeer.dataplane.service): the consumer's interface id, and `in_port`
    names the provider's service port; None for a data stream."""


@dataclass(frozen=True, slots=True)
class AckOffer:
    """A hello's ``"ack"`` map: the sender's session and the first seq this socket carries."""

    session: str
    """Random, per sending connection object: a new one means the sender restarted."""
    next: int
    """The seq of the first frame on this socket (earlier ones were acknowledged)."""
    drops: bool = False
    """The sender reads `[seq, dropped]` acks (the receiver's full-buffer drops); without it
    a receiver writes `[seq]` only, as before."""

    def to_map(self) -> dict[str, Any]:
        """The protocol map."""
        out: dict[str, Any] = {"session": self.session, "next": self.next}
        if self.drops:
            out["drops"] = True
        return out


def encode_hello(hello: Hello) -> bytes:
    """The hello map's encoding."""
    obj = {
        "v": hello.version,
        "conn": hello.conn,
        "in": hello.in_port,
        "from": hello.from_,
        "policy": hello.policy,
    }
    if hello.shm is not None:
        obj["shm"] = hello.shm
    if hello.ack is not None:
        obj["ack"] = hello.ack.to_map()
    if hello.auth is not None:
        obj["auth"] = hello.auth
    if hello.enc:
        obj["enc"] = True
    if hello.type is not None:
        obj["type"] = hello.type
    if hello.svc is not None:
        obj["svc"] = hello.svc
    return _packb(obj)


def parse_hello(obj: object) -> Hello:
    """A decoded hello map as a `Hello`; FrameError("malformed") when a field is wrong."""
    if not isinstance(obj, dict):
        raise FrameError("malformed", f"hello: expected a map, got {type(obj).__name__}")
    for key in ("conn", "in", "from"):
        if not isinstance(obj.get(key), str):
            raise FrameError("malformed", f"hello: {key!r} must be a string")
    version = obj.get("v")
    if type(version) is not int:
        raise FrameError("malformed", "hello: 'v' must be an integer")
    policy = obj.get("policy", {})
    if not isinstance(policy, dict):
        raise FrameError("malformed", "hello: 'policy' must be a map")
    ack = obj.get("ack")
    offer = None
    if ack is not None:
        if not isinstance(ack, dict):
            raise FrameError("malformed", "hello: 'ack' must be a map")
        session, nxt = ack.get("session"), ack.get("next")
        if not isinstance(session, str) or not 0 < len(session) <= 64:
            raise FrameError("malformed", "hello: 'ack.session' must be a string of 1-64 chars")
        if type(nxt) is not int or nxt < 1:
            raise FrameError("malformed", "hello: 'ack.next' must be an integer >= 1")
        drops = ack.get("drops", False)
        if type(drops) is not bool:
            raise FrameError("malformed", "hello: 'ack.drops' must be true or false")
        offer = AckOffer(session, nxt, drops)
    auth = obj.get("auth")
    if auth is not None and (type(auth) is not bytes or len(auth) != 16):
        raise FrameError("malformed", "hello: 'auth' must be a 16-byte nonce")
    enc = obj.get("enc", False)
    if type(enc) is not bool:
        raise FrameError("malformed", "hello: 'enc' must be true or false")
    kind = obj.get("type")
    if kind is not None and (not isinstance(kind, str) or not 0 < len(kind) <= 120):
        raise FrameError("malformed", "hello: 'type' must be a string of 1-120 chars")
    svc = obj.get("svc")
    if svc is not None and (not isinstance(svc, str) or not 0 < len(svc) <= 120):
        raise FrameError("malformed", "hello: 'svc' must be a string of 1-120 chars")
    return Hello(
        obj["conn"],
        obj["in"],
        obj["from"],
        policy,
        version,
        obj.get("shm"),
        offer,
        auth,
        enc,
        kind,
        svc,
    )


def encode_reply(
    error: str | None,
    *,
    shm: bool = False,
    ack: bool = False,
    auth: tuple[bytes, bytes] | None = None,
    enc: bool = False,
) -> bytes:
    """The receiver's answer to a hello: ok (saying whether it took the offered ring, whether
    it acknowledges, and its nonce and proof when it authenticates), or the error that closes
    the connection."""
    if error is not None:
        return _packb({"ok": False, "error": error})
    reply: dict[str, object] = {"ok": True}
    if shm:
        reply["shm"] = True
    if ack:
        reply["ack"] = True
    if auth is not None:
        reply["auth"] = list(auth)
    if enc:
        reply["enc"] = True
    return _packb(reply)


def reply_auth(obj: object) -> tuple[bytes, bytes] | None:
    """(nonce, proof) of a reply that has them; None without; FrameError when malformed."""
    auth = obj.get("auth") if isinstance(obj, dict) else None
    if auth is None:
        return None
    if (
        not isinstance(auth, list)
        or len(auth) != 2
        or not all(type(x) is bytes and len(x) == 16 for x in auth)
    ):
        raise FrameError("malformed", "reply: 'auth' must be [nonce, proof] of 16 bytes each")
    return auth[0], auth[1]


def parse_reply(obj: object) -> str | None:
    """None for ``{"ok": true}``, else the receiver's error; FrameError when not a reply map."""
    if not isinstance(obj, dict) or type(obj.get("ok")) is not bool:
        raise FrameError("malformed", "reply: expected a map with a boolean 'ok'")
    if obj["ok"]:
        return None
    return str(obj.get("error") or "refused without a reason")


def frame_header(seq: int) -> bytes:
    """The bytes before a frame's value: a 2-array header and seq (uint32, or uint64 if larger)."""
    return _U32(0x92, 0xCE, seq) if seq < 0x1_0000_0000 else _U64(0x92, 0xCF, seq)


def encode_value(value: object) -> bytes:
    """A value's msgpack encoding; FrameError("unencodable") for a type msgpack cannot carry."""
    try:
        return _packb(value)
    except (TypeError, ValueError, OverflowError) as exc:
        raise FrameError("unencodable", f"{type(value).__name__}: {exc}") from None


def encode_frame(seq: int, value: object) -> bytes:
    """One whole frame ``[seq, value]``."""
    return frame_header(seq) + encode_value(value)


INCOMPLETE: Final = (0, 0, 0)
"""What `big_frame_header` returns while the bytes so far could still start a big frame."""


def big_frame_header(data: bytes | memoryview, min_size: int) -> tuple[int, int, int] | None:
    """(seq, header length, value length) if `data` starts a frame whose value is a bin of at
    least `min_size` bytes; INCOMPLETE if it may, once more bytes arrive; None if it does not."""
    n = len(data)
    if n == 0:
        return INCOMPLETE
    if data[0] != 0x92:
        return None
    if n < 2:
        return INCOMPLETE
    tag = data[1]
    if tag < 0x80:
        seq, i = tag, 2
    elif 0xCC <= tag <= 0xCF:
        i = 2 + (1 << (tag - 0xCC))
        if n < i:
            return INCOMPLETE
        seq = int.from_bytes(data[2:i], "big")
    else:
        return None
    if n <= i:
        return INCOMPLETE
    width = 2 if data[i] == 0xC5 else 4 if data[i] == 0xC6 else 0
    if not width:
        return None
    if n < i + 1 + width:
        return INCOMPLETE
    size = int.from_bytes(data[i + 1 : i + 1 + width], "big")
    return (seq, i + 1 + width, size) if size >= min_size else None


class FrameDecoder:
    """Decodes one connection's byte stream: optionally a first map, then frames."""

    __slots__ = ("_end", "_error", "_fed", "_unpacker", "max_frame", "refs")

    def __init__(self, max_frame: int = DEFAULT_MAX_FRAME) -> None:
        self.max_frame = max_frame
        self.refs: Callable[[list[Any]], list[Any]] | None = None
        """Turns a three-element frame (a value held elsewhere: sdrpeer.dataplane.shm) into
        ``[seq, value]``; None: such frames are malformed."""
        self._unpacker = self._new_unpacker()
        self._fed = 0  # bytes fed so far
        self._end = 0  # stream offset where the last complete object ended
        self._error: FrameError | None = None

    def feed(self, data: bytes | memoryview) -> None:
        """Add received bytes; FrameError("oversized") if they overflow the read buffer."""
        if len(data) > READ_SLACK:
            view = memoryview(data)
            for start in range(0, len(view), READ_SLACK):
                self.feed(view[start : start + READ_SLACK])
            return
        try:
            self._unpacker.feed(data)
        except msgpack.BufferFull:
            raise FrameError("oversized", f"more than {self.max_frame} bytes pending") from None
        self._fed += len(data)

    def next_map(self) -> object | None:
        """The next complete object (a hello or reply), or None while it is still arriving."""
        try:
            obj: object = self._unpacker.unpack()
        except msgpack.OutOfData:
            if self._unpacker.tell() - self._end > HELLO_MAX:
                raise FrameError("oversized", f"hello over {HELLO_MAX} bytes") from None
            return None
        except Exception as exc:
            raise FrameError("malformed", f"{type(exc).__name__}: {exc}") from None
        self._check_size(self._unpacker.tell(), HELLO_MAX)
        return obj

    def _new_unpacker(self) -> msgpack.Unpacker:
        return msgpack.Unpacker(
            raw=False, strict_map_key=False, max_buffer_size=self.max_frame + READ_SLACK
        )

    @property
    def partial(self) -> int:
        """How many of the bytes fed belong to a frame not complete yet."""
        return self._fed - self._end

    def take_rest(self) -> bytes:
        """The bytes fed behind the last complete object, taken out (the decoder is then empty):
        what follows a handshake on an encrypted stream is not msgpack."""
        rest: bytes = self._unpacker.read_bytes(self.partial)
        self.drop_partial()
        return rest

    def drop_partial(self) -> None:
        """Forget the incomplete frame (its bytes are the caller's to handle)."""
        self._unpacker = self._new_unpacker()
        self._fed = self._end

    @property
    def at_boundary(self) -> bool:
        """True when every byte fed belongs to a frame already returned (none half-decoded)."""
        return self._end == self._fed and self._error is None

    @property
    def failed(self) -> bool:
        """True when the stream is broken: the next `frames()` raises the FrameError."""
        return self._error is not None

    def frames(self) -> list[list[Any]]:
        """Every complete frame fed so far, each a ``[seq, value]`` list, oldest first.

        A bad frame raises FrameError, but only once the good frames before it were returned:
        a call that meets one returns those, sets `failed`, and the next call raises.
        """
        if self._error is not None:
            raise self._error
        unpacker = self._unpacker
        tell = unpacker.tell
        limit = self.max_frame
        end = self._end
        refs = self.refs
        out: list[list[Any]] = []
        try:
            for obj in unpacker:
                if type(obj) is not list or len(obj) != 2 or type(obj[0]) is not int or obj[0] < 0:
                    if refs is None or type(obj) is not list or len(obj) != 3:
                        raise FrameError("malformed", f"frame is not [uint, value]: {_brief(obj)}")
                    obj = refs(obj)  # noqa: PLW2901 - the hot loop stays one name
                start, end = end, tell()
                if end - start > limit:
                    raise FrameError("oversized", f"frame of {end - start} bytes, max {limit}")
                out.append(obj)
            if tell() - end > limit:
                raise FrameError("oversized", f"frame over {limit} bytes (still arriving)")
        except FrameError as exc:
            self._error = exc
        except Exception as exc:
            self._error = FrameError("malformed", f"{type(exc).__name__}: {exc}")
        self._end = end
        if self._error is not None and not out:
            raise self._error
        return out

    def _check_size(self, end: int, limit: int) -> None:
        size, self._end = end - self._end, end
        if size > limit:
            raise FrameError("oversized", f"frame of {size} bytes, the maximum is {limit}")


def _brief(obj: object) -> str:
    text = repr(obj)
    return text if len(text) <= 60 else text[:57] + "..."
