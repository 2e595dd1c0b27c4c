"""Every key and token derived from a cluster key, in one place.

How it works: a cluster key (keyring.py) is never used as it is; each use gets its own key, one
way, so no secret of one use opens another:
- `gossip_key`: the AES-256-GCM key gossip datagrams are sealed with (HKDF-SHA256, `GOSSIP_INFO`);
- `receiver_key`: what the receiver id in a gossip datagram's header is computed with (a keyed
  BLAKE2b of the receiving robot's name; HKDF-SHA256, `RECEIVER_INFO`), so the header names the
  receiver by a pseudonym only the fleet can compute;
- `peer_token(s)`: the bearer token agents present to each other's API (HMAC-SHA256 of a fixed
  label): one per key of the ring is accepted, so a key rotation needs no restart. Without a key
  (`--insecure`) no robot shares a secret: an agent accepts no peer token and presents a random
  one of its own that no other agent takes, so no token is a public constant;
- `data_key(s)`: what component hosts authenticate their data connections with (BLAKE2b with a
  fixed personalisation), so a host never holds a cluster key and a data key cannot seal gossip;
- `transport_key`: what a new cluster key is sealed with when one agent hands it to another
  (`sdrpeer key add`, sdrpeer.keys.transport: HKDF-SHA256, `TRANSPORT_INFO`);
- `stream_keys`: the two keys of one encrypted data connection (HKDF-SHA256 of the data key both
  ends proved, salted with both handshake nonces and bound to the connection's names), so no two
  connections or directions share a key.
Nothing is imported until a function is called (`hashlib`, `hmac`, `secrets` load OpenSSL; HKDF
comes from `cryptography`): a component host imports this module with its data plane, and one
that never encrypts a stream stays without them (its idle RSS is a target).
"""

from __future__ import annotations

import functools
from collections.abc import Iterable, Sequence
from typing import Final

__all__ = [
    "GOSSIP_INFO",
    "data_key",
    "data_keys",
    "gossip_key",
    "peer_token",
    "peer_tokens",
    "receiver_key",
    "stream_keys",
    "transport_key",
]

GOSSIP_INFO: Final = b"sdrpeer gossip aes-256-gcm v1"
RECEIVER_INFO: Final = b"sdrpeer gossip receiver id v1"
_PEER_LABEL: Final = b"sdrpeer peer api v1"
_DATA_PERSON: Final = b"sdrpeer-data-v1"
_STREAM_INFO: Final = b"sdrpeer data stream aes-256-gcm v1"
TRANSPORT_INFO: Final = b"sdrpeer key transport aes-256-gcm v1"


@functools.cache
def _unkeyed() -> str:
    """The token of an agent without a key: random per process, accepted by no agent."""
    import secrets  # noqa: PLC0415 - see the module docstring

    return secrets.token_hex(32)


def _hmac_sha256(key: bytes, label: bytes) -> str:
    import hashlib  # noqa: PLC0415 - see the module docstring
    import hmac  # noqa: PLC0415

    return hmac.new(key, label, hashlib.sha256).hexdigest()


def _hkdf(key: bytes, length: int, salt: bytes | None, info: bytes) -> bytes:
    from cryptography.hazmat.primitives import hashes  # noqa: PLC0415 - only when used
    from cryptography.hazmat.primitives.kdf.hkdf import HKDF  # noqa: PLC0415

    return HKDF(hashes.SHA256(), length, salt, info).derive(key)


def gossip_key(cluster_key: bytes) -> bytes:
    """The AES-256-GCM key gossip is sealed with under `cluster_key`."""
    return _hkdf(cluster_key, 32, None, GOSSIP_INFO)


def receiver_key(cluster_key: bytes) -> bytes:
    """The BLAKE2b key gossip receiver ids are computed with under `cluster_key`."""
    return _hkdf(cluster_key, 32, None, RECEIVER_INFO)


def transport_key(cluster_key: bytes) -> bytes:
    """The AES-256-GCM key a cluster key seals a new cluster key with, agent to agent."""
    return _hkdf(cluster_key, 32, None, TRANSPORT_INFO)


def peer_token(signing_key: bytes | None) -> str:
    """The bearer token an agent presents to its peers (None: no key, a random token)."""
    if signing_key is None:
        return _unkeyed()
    return _hmac_sha256(signing_key, _PEER_LABEL)


def peer_tokens(keys: Iterable[bytes]) -> list[str]:
    """The tokens an agent accepts from its peers: one per key of its ring, so that during a key
    rotation a peer that already signs with the new key (or still with the old) gets in; none
    without a key."""
    return [_hmac_sha256(k, _PEER_LABEL) for k in keys]


def data_key(cluster_key: bytes) -> bytes:
    """The data key of one cluster key."""
    import hashlib  # noqa: PLC0415 - see the module docstring

    return hashlib.blake2b(cluster_key[:64], digest_size=32, person=_DATA_PERSON).digest()


def data_keys(keys: Iterable[bytes]) -> tuple[bytes, ...]:
    """The data keys of a ring's keys, in the ring's order (the signing key's first)."""
    return tuple(data_key(k) for k in keys)


def stream_keys(
    key: bytes, sender_nonce: bytes, receiver_nonce: bytes, names: Sequence[str]
) -> tuple[bytes, bytes]:
    """(sender -> receiver key, receiver -> sender key) of one encrypted data connection."""
    info = _STREAM_INFO + b"".join(len(n.encode()).to_bytes(4, "big") + n.encode() for n in names)
    both = _hkdf(key, 64, sender_nonce + receiver_nonce, info)
    return both[:32], both[32:]
