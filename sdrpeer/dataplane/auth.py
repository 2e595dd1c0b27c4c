"""Authenticated data connections: both ends prove they hold a data key of the cluster.

How it works (docs/protocol.md section 2, "Authentication"): the agent derives one data key
from each key of its cluster keyring (sdrpeer.keys.datakeys) and gives them to its hosts
(SDRPEER_DATA_KEYS, hex, the signing key first; a running host gets new ones with the
`data_keys` command when the agent's keys rotate). A sender with keys puts a fresh random nonce
in its hello; the receiver answers with its own nonce and a MAC over both (proving it holds a
key); the sender checks it under every key it has and writes, before any frame, a MAC over both
nonces and the connection's names under the key that matched (proving it holds one too). Nonces
are fresh on both sides, so a captured handshake replayed opens nothing. A receiver with keys
refuses a hello without a nonce; a sender with keys refuses a receiver that does not prove
itself. The MAC is keyed BLAKE2b (16 bytes), which needs no OpenSSL (hosts stay small).

What follows the handshake on TCP is encrypted and authenticated (sdrpeer.dataplane.seal) under
keys derived from the data key both proofs used (`check_receiver` and `check_sender` return it);
same-robot Unix sockets and shared memory stay in clear. Both proofs also cover whether what
follows is encrypted (`proof_parts`: each side's own view, "enc" or "clear"), so a man in the
middle who flips the hello's ``enc`` (or the policy's ``encrypt``) makes the proofs fail: a
downgrade is refused, never accepted.
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import TYPE_CHECKING, Final

if TYPE_CHECKING:
    from sdrpeer.dataplane.frames import Hello

try:  # the C module itself: `hashlib` would load OpenSSL into every host (sdrpeer.host.lean)
    from _blake2 import blake2b
except ImportError:  # pragma: no cover - an interpreter without it
    from hashlib import blake2b

__all__ = ["DataAuth", "proof_names", "proof_parts"]

NONCE: Final = 16
MAC: Final = 16


def _mac(key: bytes, *parts: bytes) -> bytes:
    h = blake2b(key=key, digest_size=MAC)
    for part in parts:
        h.update(len(part).to_bytes(4, "big"))
        h.update(part)
    return h.digest()


def _same(a: bytes, b: bytes) -> bool:
    """Constant-time comparison (hmac.compare_digest would load OpenSSL into every host)."""
    if len(a) != len(b):
        return False
    diff = 0
    for x, y in zip(a, b, strict=True):
        diff |= x ^ y
    return diff == 0


class DataAuth:
    """The data keys of one host (mutable: the agent rotates them)."""

    def __init__(self, keys: Sequence[bytes]) -> None:
        self.keys: list[bytes] = list(keys)
        """The keys, the signing one first; empty: connections are not authenticated."""

    @property
    def enabled(self) -> bool:
        """True when this host authenticates its connections."""
        return bool(self.keys)

    @staticmethod
    def nonce() -> bytes:
        """A fresh random nonce."""
        return os.urandom(NONCE)

    def receiver_proof(self, sender_nonce: bytes, nonce: bytes, names: Sequence[str]) -> bytes:
        """The receiver's MAC (its signing key) for its reply."""
        return _mac(self.keys[0], b"receiver", sender_nonce, nonce, *(n.encode() for n in names))

    def check_receiver(
        self, sender_nonce: bytes, nonce: bytes, names: Sequence[str], proof: bytes
    ) -> bytes | None:
        """The key under which the receiver's proof holds, or None."""
        parts = [n.encode() for n in names]
        for key in self.keys:
            if _same(_mac(key, b"receiver", sender_nonce, nonce, *parts), proof):
                return key
        return None

    @staticmethod
    def sender_proof(key: bytes, nonce: bytes, sender_nonce: bytes, names: Sequence[str]) -> bytes:
        """The sender's MAC over both nonces and the connection's names."""
        return _mac(key, b"sender", nonce, sender_nonce, *(n.encode() for n in names))

    def check_sender(
        self, nonce: bytes, sender_nonce: bytes, names: Sequence[str], proof: bytes
    ) -> bytes | None:
        """The key under which the sender's proof holds, or None."""
        for key in self.keys:
            if _same(self.sender_proof(key, nonce, sender_nonce, names), proof):
                return key
        return None


def proof_names(hello: Hello) -> tuple[str, ...]:
    """What both proofs cover besides the nonces: the connection, its ports and, for an
    acknowledged stream, the sender's session and first seq (so neither can be rewritten)."""
    ack = hello.ack
    extra = ("", "") if ack is None else (ack.session, str(ack.next))
    return (hello.conn, hello.in_port, hello.from_, *extra)


def proof_parts(hello: Hello, sealed: bool) -> tuple[str, ...]:
    """What both MACs cover besides the nonces: `proof_names`, then whether the stream is
    encrypted after the sender's proof ("enc" or "clear", as this side sees it), so that a
    flipped ``enc`` flag fails the proof instead of downgrading the stream. (The stream keys
    are derived over `proof_names` alone.)"""
    return (*proof_names(hello), "enc" if sealed else "clear")
