"""Wire format: gossip packets <-> sealed datagrams. The only codec for `gossip.messages`.

How it works
------------
A datagram is a fixed 23-byte header, then the msgpack body encrypted with AES-256-GCM and its
16-byte tag (39 bytes in all besides the body)::

    b"SP" | version (1) | key id (4) | nonce (12) | receiver id (4) | AES-GCM(body) | tag (16)

- *version* is `PROTOCOL_VERSION`; any other value is dropped as "version".
- *key id* is the first 4 bytes of sha256(key) of the cluster key that sealed; all zeros when
  not sealed (`--insecure`: then the body follows the header in clear, without a tag).
- *nonce* is the codec's 4 random bytes (drawn when it is made) and the datagram's 8-byte seq:
  unique per datagram under one key without coordination (seqs only rise, also across
  restarts).
- *receiver id* names the robot the datagram is addressed to (the packet's `to`) by a keyed
  pseudonym (`Keyring.receiver_ids`: BLAKE2b of its name under a key derived from the cluster
  key), or is all zeros for a datagram to whoever listens at an address (a seed joined by
  address, whose name the sender does not know yet). A receiver drops a datagram bound to
  another robot as "wrong_receiver" before any decryption. The associated data of the AEAD is
  the header *and the receiver's name* (nothing for an unbound datagram): a datagram captured on
  its way to one robot and replayed to another does not open there, even if two robots'
  pseudonyms collided, and no header byte can be altered either. Nothing of the body — names,
  metrics, plans — is readable without the key; the pseudonym only tells which datagrams go to
  the same robot, as their destination address does. In clear (`--insecure`) the receiver id
  only says bound (all 0xff) or not (zeros): nothing is authenticated there anyway.
- *body* is a short *stream* of msgpack arrays, not one nested array:
  the head ``[tag, sender, seq, ts_ms, *fields]``, then (Sync only) one array per entry, then
  one array per piggybacked update ``[utag, *fields]``. A ping's head may end with the sender's
  vitals revision ``version, revision, payload``. Keeping every array small and flat lets
  the decoder cap each array at `MAX_FIELDS` elements, so a hostile datagram cannot make msgpack
  preallocate megabytes of nested lists; and a packet's size is exactly its head plus the sum of
  `encoded_size(u)` of its updates.

Checks on receive, cheapest and safest first: size, magic, version, key id, receiver id (ours or
none), tag (the body is decrypted and authenticated before it is parsed), body (every field
type-checked), then freshness (ts no older than the window before the cluster time, nor than
this robot's life: `begin_life`) and replay (per-sender sliding window of the last
`REPLAY_WINDOW` seqs, as in IPsec; the windows are this robot's own and this life's, which is
why a datagram must be bound to its receiver, and why one sent before this life is stale).

Time: timestamps are in cluster time (`replay.ClusterClock`: the wall clock plus an offset that
only grows to the newest authenticated timestamp accepted), so robots need no common clock;
`WireError.sender_behind` tells the shell when an authenticated datagram was stale and newer than
anything its sender sent us before (its sender is behind; a replay of recorded traffic is never
newer than what followed it, so it is not answered).

A failure raises `WireError(reason)` and is counted in `Codec.counters[reason]`; nothing else
escapes `decode`.

Keys: a `Keyring` holds the cluster keys; the first seals, every one opens. To rotate: add the
new key second everywhere (both open), then move it first everywhere (it seals, the old still
opens), then remove the old one. `Codec(sender, None)` is the explicit insecure choice: it sends
datagrams in clear and accepts clear ones (a sealed one it cannot open: "unknown_key").

Seqs: each `Codec` numbers its datagrams from `seq_start` (the shell passes wall-clock
microseconds, so seqs keep rising across restarts); receivers track them per sender name, so a
codec only encodes packets whose `sender` is its own.
"""

from __future__ import annotations

import os
from collections import Counter

import msgpack

from sdrpeer.errors import WireError
from sdrpeer.gossip.messages import (
    Ack,
    Addr,
    Alive,
    Dead,
    Digest,
    Event,
    Gossip,
    Nack,
    Packet,
    Ping,
    PingReq,
    Record,
    Suspect,
    Sync,
    SyncEntry,
    Update,
    VitalsRevision,
)
from sdrpeer.gossip.replay import REPLAY_WINDOW, ClusterClock, ReplayGuard
from sdrpeer.keys.keyring import (
    INSECURE_KEY_ID,
    KEY_ID_SIZE,
    MIN_KEY_SIZE,
    NO_RECEIVER,
    NONCE_SIZE,
    RECEIVER_ID_SIZE,
    TAG_SIZE,
    Keyring,
    format_key,
    key_id,
    parse_key,
)
from sdrpeer.vocabulary import MemberState

__all__ = [  # the keyring and replay guard live in their own modules; re-exported here
    "HEADER_SIZE",
    "INSECURE_KEY_ID",
    "KEY_ID_SIZE",
    "MIN_KEY_SIZE",
    "OVERHEAD",
    "PROTOCOL_VERSION",
    "REASONS",
    "REPLAY_WINDOW",
    "Codec",
    "Keyring",
    "ReplayGuard",
    "decode_update",
    "encode_update",
    "encoded_size",
    "format_key",
    "key_id",
    "packet_body",
    "parse_key",
]

PROTOCOL_VERSION = 4
"""Bumped on any incompatible change of the header or body layout (2: digests, vitals on pings,
format-2 records; 3: AES-GCM instead of an HMAC, format-3 records; 4: datagrams bound to their
receiver)."""
MAGIC = b"SP"
HEADER_SIZE = len(MAGIC) + 1 + KEY_ID_SIZE + NONCE_SIZE + RECEIVER_ID_SIZE
"""Bytes the envelope adds before the body (23)."""
OVERHEAD = HEADER_SIZE + TAG_SIZE
"""Bytes a sealed datagram adds to its body (39; `GossipConfig.packet_overhead` budgets 48)."""
MAX_FIELDS = 32
"""Largest msgpack array or map accepted anywhere in a body (a head has at most 8 fields)."""
MAX_NAME = 255
"""Longest robot name, host or event kind, in characters."""

REASONS = (
    "oversized",
    "malformed",
    "version",
    "unauthenticated",
    "unknown_key",
    "wrong_receiver",
    "stale",
    "replayed",
)
"""Every reason `Codec.decode` can reject a datagram for."""

# Packet and update tags (small ints on the wire; never reuse a retired one).
T_PING, T_PINGREQ, T_ACK, T_NACK, T_GOSSIP, T_SYNC, T_DIGEST = range(7)
U_ALIVE, U_SUSPECT, U_DEAD, U_RECORD, U_EVENT = range(5)
_MEMBER_CODES: dict[MemberState, int] = {
    MemberState.ALIVE: 0,
    MemberState.SUSPECT: 1,
    MemberState.DEAD: 2,
    MemberState.LEFT: 3,
}
"""Member states in a sync entry (small ints on the wire; never reuse a retired one)."""
_MEMBER_OF_CODE = {code: state for state, code in _MEMBER_CODES.items()}

_PACKER = msgpack.Packer(use_bin_type=True)
_pack = _PACKER.pack
_SEQ_MASK = (1 << 64) - 1
_KID = slice(len(MAGIC) + 1, len(MAGIC) + 1 + KEY_ID_SIZE)
_NONCE = slice(_KID.stop, _KID.stop + NONCE_SIZE)
_TO = slice(_NONCE.stop, HEADER_SIZE)
_BOUND_IN_CLEAR = b"\xff" * RECEIVER_ID_SIZE
"""The receiver id of a bound datagram in clear (`--insecure`: no key to name the receiver)."""


def encode_update(u: Update) -> list[object]:
    """`u` as the msgpack array sent on the wire: [utag, *fields]."""
    if isinstance(u, Alive):
        return [U_ALIVE, u.name, u.addr, u.incarnation]
    if isinstance(u, Suspect):
        return [U_SUSPECT, u.name, u.incarnation, u.source]
    if isinstance(u, Dead):
        return [U_DEAD, u.name, u.incarnation, u.source]
    if isinstance(u, Record):
        return [U_RECORD, u.name, u.version, u.payload]
    if isinstance(u, Event):
        return [U_EVENT, u.source, u.seq, u.kind, u.payload]
    raise TypeError(f"not an update: {u!r}")


def encoded_size(u: Update) -> int:
    """Bytes `u` adds to a datagram body."""
    return len(_pack(encode_update(u)))


def _head(p: Packet, seq: int, ts_ms: int) -> tuple[object, ...]:
    if isinstance(p, Ping):
        v = p.vitals
        if v is None:
            return (T_PING, p.sender, seq, ts_ms, p.seq, p.target)
        return (T_PING, p.sender, seq, ts_ms, p.seq, p.target, v.version, v.revision, v.payload)
    if isinstance(p, PingReq):
        return (T_PINGREQ, p.sender, seq, ts_ms, p.seq, p.target, p.target_addr, p.want_nack)
    if isinstance(p, Ack):
        return (T_ACK, p.sender, seq, ts_ms, p.seq)
    if isinstance(p, Nack):
        return (T_NACK, p.sender, seq, ts_ms, p.seq)
    if isinstance(p, Gossip):
        return (T_GOSSIP, p.sender, seq, ts_ms)
    if isinstance(p, Sync):
        return (T_SYNC, p.sender, seq, ts_ms, p.reply, len(p.entries))
    if isinstance(p, Digest):
        return (T_DIGEST, p.sender, seq, ts_ms, p.digest, p.count)
    raise TypeError(f"not a packet: {p!r}")


# Placeholders with the wire width of real seqs (microseconds) and timestamps (milliseconds).
_TYPICAL_SEQ = 1 << 62
_TYPICAL_TS_MS = 1 << 42


def packet_body(packet: Packet, seq: int = _TYPICAL_SEQ, ts_ms: int = _TYPICAL_TS_MS) -> bytes:
    """The msgpack body of `packet`, in clear (a sealed datagram is `OVERHEAD` bytes more).

    The default seq and ts_ms are placeholders as wide on the wire as real ones, so the length
    is that of a real datagram body.
    """
    parts = [_pack(_head(packet, seq, ts_ms))]
    if isinstance(packet, Sync):
        parts.extend(_pack((n, a, i, _MEMBER_CODES[s], v)) for n, a, i, s, v in packet.entries)
    parts.extend([_pack(encode_update(u)) for u in packet.updates])
    return b"".join(parts)


# ---------------------------------------------------------------------------------------------
# Body decoding: every field is checked; a violation raises WireError("malformed").


def _bad(what: str, value: object) -> WireError:
    return WireError("malformed", f"bad {what}: {value!r:.60}")


def _name(v: object, what: str) -> str:
    if type(v) is not str or not 0 < len(v) <= MAX_NAME:
        raise _bad(what, v)
    return v


def _uint(v: object, what: str) -> int:
    if type(v) is not int or v < 0:
        raise _bad(what, v)
    return v


def _bool(v: object, what: str) -> bool:
    if type(v) is not bool:
        raise _bad(what, v)
    return v


def _bytes(v: object, what: str) -> bytes:
    if type(v) is not bytes:
        raise _bad(what, v)
    return v


def _addr(v: object) -> Addr:
    if type(v) is not list or len(v) != 2:
        raise _bad("addr", v)
    port = v[1]
    if type(port) is not int or not 0 <= port <= 65535:
        raise _bad("port", port)
    return (_name(v[0], "host"), port)


def decode_update(obj: object) -> Update | None:
    """The update an array from the wire stands for; None for an unknown (newer) update tag.

    Trailing fields beyond the known ones are ignored (a newer peer may append some).
    """
    if type(obj) is not list or not obj or type(obj[0]) is not int:
        raise _bad("update", obj)
    tag = obj[0]
    n = len(obj)
    if tag == U_ALIVE and n >= 4:
        return Alive(_name(obj[1], "name"), _addr(obj[2]), _uint(obj[3], "incarnation"))
    if tag == U_SUSPECT and n >= 4:
        return Suspect(_name(obj[1], "name"), _uint(obj[2], "incarnation"), _name(obj[3], "source"))
    if tag == U_DEAD and n >= 4:
        return Dead(_name(obj[1], "name"), _uint(obj[2], "incarnation"), _name(obj[3], "source"))
    if tag == U_RECORD and n >= 4:
        return Record(_name(obj[1], "name"), _uint(obj[2], "version"), _bytes(obj[3], "payload"))
    if tag == U_EVENT and n >= 5:
        return Event(
            _name(obj[1], "source"),
            _uint(obj[2], "seq"),
            _name(obj[3], "kind"),
            _bytes(obj[4], "payload"),
        )
    if U_ALIVE <= tag <= U_EVENT:
        raise _bad("update (too few fields)", obj)
    return None


def _entry(obj: object) -> SyncEntry:
    if type(obj) is not list or len(obj) < 5:
        raise _bad("sync entry", obj)
    state = obj[3]
    if type(state) is not int or state not in _MEMBER_OF_CODE:
        raise _bad("member state", state)
    return (
        _name(obj[0], "name"),
        _addr(obj[1]),
        _uint(obj[2], "incarnation"),
        _MEMBER_OF_CODE[state],
        _uint(obj[4], "record version"),
    )


# Fields in a head after [tag, sender, seq, ts_ms], per packet tag.
_HEAD_FIELDS = {T_PING: 2, T_PINGREQ: 4, T_ACK: 1, T_NACK: 1, T_GOSSIP: 0, T_SYNC: 2, T_DIGEST: 2}
_DIGEST_MAX = (1 << 64) - 1


def _new_unpacker(max_size: int) -> msgpack.Unpacker:
    """An unpacker that refuses any array or map longer than MAX_FIELDS (bounded allocation)."""
    return msgpack.Unpacker(
        None,
        raw=False,
        max_buffer_size=max_size,
        max_str_len=max_size,
        max_bin_len=max_size,
        max_ext_len=max_size,
        max_array_len=MAX_FIELDS,
        max_map_len=MAX_FIELDS,
    )


def _parse_body(
    unpacker: msgpack.Unpacker, body: bytes, to: str = ""
) -> tuple[Packet, int, int, int]:
    """(packet, seq, ts_ms, unknown updates skipped) from a body in clear, addressed `to`.

    `unpacker` must be empty; it is empty again on success (on failure, throw it away).
    """
    start = unpacker.tell()
    unpacker.feed(body)
    head = unpacker.unpack()
    if type(head) is not list or len(head) < 4 or type(head[0]) is not int:
        raise _bad("head", head)
    tag = head[0]
    extra = _HEAD_FIELDS.get(tag)
    if extra is None:
        raise WireError("malformed", f"unknown packet tag {tag}")
    if len(head) < 4 + extra:
        raise _bad("head (too few fields)", head)
    sender = _name(head[1], "sender")
    seq = _uint(head[2], "seq")
    ts_ms = _uint(head[3], "timestamp")
    entries: tuple[SyncEntry, ...] = ()
    if tag == T_SYNC:
        entries = tuple([_entry(unpacker.unpack()) for _ in range(_uint(head[5], "entries"))])
    updates: list[Update] = []
    unknown = 0
    end = start + len(body)
    while unpacker.tell() < end:  # (iterating would silently stop at a truncated update)
        u = decode_update(unpacker.unpack())
        if u is None:
            unknown += 1
        else:
            updates.append(u)
    ups = tuple(updates)
    packet: Packet
    if tag == T_PING:
        vitals = None
        if len(head) >= 9:
            vitals = VitalsRevision(
                _uint(head[6], "vitals version"),
                _uint(head[7], "vitals revision"),
                _bytes(head[8], "vitals"),
            )
        packet = Ping(sender, _uint(head[4], "probe seq"), _name(head[5], "target"), ups, vitals)
    elif tag == T_PINGREQ:
        packet = PingReq(
            sender,
            _uint(head[4], "probe seq"),
            _name(head[5], "target"),
            _addr(head[6]),
            _bool(head[7], "want_nack"),
            ups,
            to,
        )
    elif tag == T_ACK:
        packet = Ack(sender, _uint(head[4], "probe seq"), ups, to)
    elif tag == T_NACK:
        packet = Nack(sender, _uint(head[4], "probe seq"), ups, to)
    elif tag == T_GOSSIP:
        packet = Gossip(sender, ups, to)
    elif tag == T_DIGEST:
        digest = _uint(head[4], "digest")
        if digest > _DIGEST_MAX:
            raise _bad("digest", digest)
        packet = Digest(sender, digest, _uint(head[5], "count"), ups, to)
    else:
        packet = Sync(sender, _bool(head[4], "reply"), entries, ups, to)
    return packet, seq, ts_ms, unknown


# ---------------------------------------------------------------------------------------------
# The codec


class Codec:
    """Encodes this robot's packets into datagrams and checks and decodes incoming ones."""

    def __init__(
        self,
        sender: str,
        keyring: Keyring | None,
        *,
        max_datagram: int = 65000,
        freshness_s: float = 30.0,
        seq_start: int | None = None,
        max_senders: int = 4096,
    ) -> None:
        if max_datagram <= OVERHEAD:
            raise ValueError(f"max_datagram must exceed the {OVERHEAD}-byte envelope")
        self.sender = sender
        """The robot whose packets this codec encodes (packets from others are refused)."""
        self.keyring = keyring
        """Keys that sign and verify (assign a new ring to rotate keys while running); None is
        the explicit insecure mode."""
        self.max_datagram = max_datagram
        """Largest datagram sent or accepted, header included."""
        self.guard = ReplayGuard(freshness_s, max_senders)
        """Freshness and per-sender replay window of incoming datagrams."""
        self.counters: Counter[str] = Counter()
        """Rejections by reason, plus "accepted", "sent", "unknown_update" (updates skipped),
        "send_oversized" (packets too big to encode) and "clock_advanced" (datagrams that moved
        the cluster time on)."""
        self._seq = seq_start
        self.clock = ClusterClock()
        """This robot's cluster time (`clock.offset_ms` is kept across restarts by the agent)."""
        self._unpacker = _new_unpacker(max_datagram)
        self._insecure_header = MAGIC + bytes([PROTOCOL_VERSION]) + bytes(HEADER_SIZE - 3)
        self._nonce_prefix = os.urandom(NONCE_SIZE - 8)
        """This codec's part of every nonce (with the seq: unique per datagram under a key)."""

    @property
    def secure(self) -> bool:
        """Whether datagrams are signed and verified."""
        return self.keyring is not None

    def begin_life(self, now_wall: float) -> None:
        """This robot's life begins at `now_wall` (call it once the cluster-time offset is
        loaded): a datagram stamped earlier was sent to an earlier life of this robot, whose
        replay windows are gone, and is refused as stale from now on."""
        self.guard.life_start_ms = self.clock.now_ms(now_wall)

    def reject(
        self, reason: str, detail: str = "", *, sender_behind: bool = False, sender: str = ""
    ) -> WireError:
        """Count a rejection under `reason` and return the error to raise."""
        self.counters[reason] += 1
        return WireError(reason, detail, sender_behind=sender_behind, sender=sender)

    def encode(self, packet: Packet, now_wall: float) -> bytes:
        """The datagram carrying `packet`, with the next seq and `now_wall` as its timestamp,
        bound to its receiver `packet.to` (none when "")."""
        if packet.sender != self.sender:
            raise ValueError(f"codec of {self.sender!r} cannot send as {packet.sender!r}")
        seq = int(now_wall * 1e6) if self._seq is None else self._seq
        self._seq = seq + 1
        body = packet_body(packet, seq, self.clock.now_ms(now_wall))
        if len(body) + OVERHEAD > self.max_datagram:
            self.counters["send_oversized"] += 1
            raise WireError(
                "oversized",
                f"{type(packet).__name__} of {len(body) + OVERHEAD} bytes > {self.max_datagram}",
            )
        self.counters["sent"] += 1
        return self.seal(body, packet.to, seq)

    def seal(self, body: bytes, to: str, seq: int) -> bytes:
        """The datagram around `body` (a packet body in clear) bound to receiver `to` ("": to
        whoever listens at the address), its nonce made of `seq` (`encode` uses it; tools/fuzz.py
        seals mutated bodies with it)."""
        if self.keyring is None:
            rid = _BOUND_IN_CLEAR if to else NO_RECEIVER
            return self._insecure_header[: _TO.start] + rid + body
        nonce = self._nonce_prefix + (seq & _SEQ_MASK).to_bytes(8, "big")
        rid = self.keyring.receiver_ids(to)[0] if to else NO_RECEIVER
        header = MAGIC + bytes([PROTOCOL_VERSION]) + self.keyring.key_ids[0] + nonce + rid
        return header + self.keyring.seal(nonce, body, header + to.encode())

    def decode(self, data: bytes | bytearray | memoryview, now_wall: float) -> Packet:
        """The packet in datagram `data`, received at `now_wall`; else WireError (counted)."""
        if type(data) is not bytes:
            data = bytes(data)  # a bytearray or memoryview: key ids must be hashable
        size = len(data)
        if size > self.max_datagram:
            raise self.reject("oversized", f"{size} bytes > {self.max_datagram}")
        if size < HEADER_SIZE or data[:2] != MAGIC:
            raise self.reject("malformed", "not an sdrpeer datagram")
        if data[2] != PROTOCOL_VERSION:
            raise self.reject("version", f"protocol version {data[2]}, {PROTOCOL_VERSION} known")
        kid = data[_KID]
        to = self.sender
        if self.keyring is None:
            if kid != INSECURE_KEY_ID:
                raise self.reject("unknown_key", f"sealed under key id {kid.hex()}: no key here")
            if data[_TO] == NO_RECEIVER:
                to = ""  # else bound to a robot a clear datagram cannot name: taken as us
            body = data[HEADER_SIZE:]
        else:
            if kid == INSECURE_KEY_ID:
                raise self.reject("unauthenticated", "datagram in clear")
            if not self.keyring.knows(kid):
                raise self.reject("unknown_key", f"key id {kid.hex()}")
            if size < OVERHEAD:
                raise self.reject("malformed", "shorter than a tag")
            rid = data[_TO]
            if rid == NO_RECEIVER:
                to = ""  # to whoever listens at our address: a join by address
            elif rid not in self.keyring.receiver_ids(to, kid):
                raise self.reject("wrong_receiver", f"receiver id {rid.hex()}: not ours")
            header = data[:HEADER_SIZE]
            opened = self.keyring.open(kid, data[_NONCE], data[HEADER_SIZE:], header + to.encode())
            if opened is None:
                raise self.reject("unauthenticated", f"bad tag under key id {kid.hex()}")
            body = opened
        try:
            packet, seq, ts_ms, unknown = _parse_body(self._unpacker, body, to)
        except BaseException as e:
            self._unpacker = _new_unpacker(self.max_datagram)  # it may hold half a body
            if isinstance(e, WireError):
                raise self.reject(e.reason, e.detail) from None
            if isinstance(e, Exception):  # msgpack's ValueError, OutOfData, ...: all malformed
                raise self.reject("malformed", f"{type(e).__name__}: {e}"[:120]) from None
            raise
        cluster_ms = self.clock.now_ms(now_wall)
        secure = self.keyring is not None
        if self.clock.too_new(ts_ms, cluster_ms, self.guard.freshness_ms, authenticated=secure):
            raise self.reject("stale", f"from {packet.sender!r}: ts {ts_ms} ms in the future")
        reason = self.guard.check(packet.sender, seq, ts_ms, cluster_ms)
        if reason is not None:
            # Stale and newer than all its sender sent us: its clock is behind, not a replay.
            behind = reason == "stale" and secure and self.guard.newer(packet.sender, seq)
            detail = f"from {packet.sender!r}, seq {seq}, ts {ts_ms} ms"
            raise self.reject(reason, detail, sender_behind=behind, sender=packet.sender)
        if secure and self.clock.observe(ts_ms, cluster_ms):
            self.counters["clock_advanced"] += 1
        self.counters["accepted"] += 1
        if unknown:
            self.counters["unknown_update"] += unknown
        return packet
