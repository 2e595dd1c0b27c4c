"""A cluster key handed from one agent to another (`sdrpeer key add`), sealed under the current
cluster key.

How it works: the agent the operator asked seals the new key with AES-256-GCM under
`transport_key` of its own sealing key (HKDF-SHA256, sdrpeer.keys.derive), with a fresh random
nonce, bound to the receiving robot's name (the associated data), and posts
`{"by": key id, "nonce": hex, "sealed": hex}` to that robot's API with the peer token. The
receiver opens it with the key of its ring that has id `by`. HTTP between agents is plain, so a
neighbour on the radio sees the sealed bytes only: without a cluster key it learns nothing of the
new one, and a sealed key posted to another robot does not open there.
"""

from __future__ import annotations

import os
from typing import Any, Final

from sdrpeer.errors import ConfigError
from sdrpeer.keys.derive import transport_key
from sdrpeer.keys.keyring import MIN_KEY_SIZE, Keyring, key_id, parse_key_id

__all__ = ["open_key", "seal_key"]

_AAD: Final = b"sdrpeer key for "
_NONCE: Final = 12


def _aad(robot: str) -> bytes:
    return _AAD + robot.encode()


def seal_key(ring: Keyring, key: bytes, robot: str) -> dict[str, str]:
    """`key` sealed under the ring's sealing key, for `robot` only."""
    from cryptography.hazmat.primitives.ciphers.aead import AESGCM  # noqa: PLC0415 - see keyring

    nonce = os.urandom(_NONCE)
    sealed = AESGCM(transport_key(ring.signing_key)).encrypt(nonce, key, _aad(robot))
    return {"by": key_id(ring.signing_key).hex(), "nonce": nonce.hex(), "sealed": sealed.hex()}


def open_key(ring: Keyring, doc: Any, robot: str) -> bytes:
    """The key sealed in `doc` for `robot`; ConfigError saying which field is wrong, or that no
    key of the ring opens it."""
    from cryptography.exceptions import InvalidTag  # noqa: PLC0415
    from cryptography.hazmat.primitives.ciphers.aead import AESGCM  # noqa: PLC0415

    if not isinstance(doc, dict):
        raise ConfigError('field "key": expected {"by": ..., "nonce": ..., "sealed": ...}')
    try:
        by = parse_key_id(str(doc.get("by", "")))
        nonce = bytes.fromhex(str(doc.get("nonce", "")))
        sealed = bytes.fromhex(str(doc.get("sealed", "")))
    except ValueError as exc:
        raise ConfigError(f'field "key": {exc}') from None
    if len(nonce) != _NONCE:
        raise ConfigError(f'field "key.nonce": expected {_NONCE} bytes in hex')
    sealer = ring.find(by)
    if sealer is None:
        raise ConfigError(f'field "key.by": no key with id {by.hex()} on this robot')
    try:
        key = AESGCM(transport_key(sealer)).decrypt(nonce, sealed, _aad(robot))
    except InvalidTag:
        raise ConfigError(
            'field "key": does not open (altered, or sealed for another robot)'
        ) from None
    if len(key) < MIN_KEY_SIZE:
        raise ConfigError(f'field "key": {len(key)} bytes, at least {MIN_KEY_SIZE} needed')
    return bytes(key)
