"""Cluster keys: a keyring whose first key seals and every key opens (rotation without downtime),
with the key file format.

How it works: a key is at least 16 random bytes, identified on the wire by the first 4 bytes of
its SHA-256 (the key id). Gossip is sealed with AES-256-GCM (authenticated encryption, as Serf
does), under a key derived from each cluster key with HKDF-SHA256 (`GOSSIP_INFO`), from the
`cryptography` package: `Keyring.seal` uses the first key, `Keyring.open` looks the key up by id
(two keys whose ids collide are both tried); `Keyring.receiver_ids` names the robot a datagram
is addressed to by a keyed pseudonym (sdrpeer.gossip.wire binds datagrams to it). Rotation: add
the new key second everywhere (both open), move it first everywhere (it seals, the old one still
opens), then remove the old (`with_key`, `with_primary`, `without` make each step's ring;
`sdrpeer key add|primary|retire` spreads one to the fleet, sdrpeer.agent.keyadmin). Key files
hold one key a line, hex or base64 (a `hex:`/`base64:` prefix says which), `#` comments.
`cryptography` is imported only when a keyring first seals or opens.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import os
import re
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sdrpeer.errors import ConfigError
from sdrpeer.keys.derive import gossip_key, receiver_key

KEY_ID_SIZE = 4
RECEIVER_ID_SIZE = 4
"""Bytes of a receiver id: the keyed pseudonym of the robot a gossip datagram is addressed to."""
NO_RECEIVER = b"\0" * RECEIVER_ID_SIZE
"""The receiver id of a datagram addressed to whoever listens at an address (a seed)."""
_RECEIVER_CACHE = 4096
NONCE_SIZE = 12
"""AES-GCM's nonce: unique per datagram under one key (the codec makes it; see
sdrpeer.gossip.wire)."""
TAG_SIZE = 16
"""AES-GCM's authentication tag, at the end of every sealed body."""
"""HKDF's `info` for the gossip key derived from a cluster key (other uses derive their own)."""
INSECURE_KEY_ID = b"\0" * KEY_ID_SIZE
MIN_KEY_SIZE = 16
_HEX = re.compile(r"(?:[0-9a-fA-F]{2})+")


def key_id(key: bytes) -> bytes:
    """The 4-byte id of `key` sent in every datagram it seals: sha256(key)[:4]."""
    return hashlib.sha256(key).digest()[:KEY_ID_SIZE]


def parse_key_id(text: str) -> bytes:
    """A key id as printed (8 hex digits); ValueError saying what is expected."""
    text = text.strip().lower()
    if len(text) != 2 * KEY_ID_SIZE or not _HEX.fullmatch(text):
        raise ValueError(f"{text!r} is not a key id (8 hex digits, as `sdrpeer key list` shows)")
    return bytes.fromhex(text)


def format_key(key: bytes) -> str:
    """`key` as a line for a key file (lowercase hex)."""
    return key.hex()


def parse_key(text: str) -> bytes:
    """A key written as hex or base64 (prefix "hex:" or "base64:" to say which; else detected)."""
    if text.startswith("hex:"):
        return bytes.fromhex(text[4:])
    if text.startswith("base64:"):
        return base64.b64decode(text[7:], validate=True)
    if _HEX.fullmatch(text):
        return bytes.fromhex(text)
    return base64.b64decode(text, validate=True)


class Keyring:
    """Cluster keys: the first seals, every key opens (so keys rotate without downtime)."""

    def __init__(self, keys: Sequence[bytes]) -> None:
        unique = list(dict.fromkeys(bytes(k) for k in keys))
        if not unique:
            raise ConfigError("keyring: at least one key is needed")
        for i, key in enumerate(unique):
            if len(key) < MIN_KEY_SIZE:
                raise ConfigError(
                    f"keyring: key #{i + 1} has {len(key)} bytes, at least {MIN_KEY_SIZE} needed"
                )
        self._keys = tuple(unique)
        self._ids = tuple(key_id(k) for k in unique)
        if INSECURE_KEY_ID in self._ids:
            raise ConfigError("keyring: a key has the all-zero key id of unsigned datagrams")
        self._aeads: dict[bytes, list[Any]] | None = None
        """Key id -> the AES-GCM ciphers of the keys with that id (built on first use)."""
        self._receiver_keys: dict[bytes, list[bytes]] | None = None
        self._receiver_ids: dict[tuple[bytes, str], tuple[bytes, ...]] = {}

    @property
    def signing_key(self) -> bytes:
        """The key that seals outgoing datagrams (the first one)."""
        return self._keys[0]

    @property
    def keys(self) -> tuple[bytes, ...]:
        """Every key, the signing key first (to derive per-key secrets; never logged)."""
        return self._keys

    @property
    def key_ids(self) -> tuple[bytes, ...]:
        """Ids of every key, the signing key's first."""
        return self._ids

    def __len__(self) -> int:
        """Number of distinct keys."""
        return len(self._keys)

    def __repr__(self) -> str:
        """Key ids only: a keyring never prints its keys."""
        return f"Keyring(key_ids=[{', '.join(k.hex() for k in self._ids)}])"

    def knows(self, kid: bytes) -> bool:
        """Whether some key in the ring has id `kid`."""
        return kid in self._ids

    def _ciphers(self) -> dict[bytes, list[Any]]:
        if self._aeads is None:
            from cryptography.hazmat.primitives.ciphers.aead import AESGCM  # noqa: PLC0415

            aeads: dict[bytes, list[Any]] = {}
            for kid, key in zip(self._ids, self._keys, strict=True):
                aeads.setdefault(kid, []).append(AESGCM(gossip_key(key)))
            self._aeads = aeads
        return self._aeads

    def seal(self, nonce: bytes, data: bytes, aad: bytes) -> bytes:
        """`data` encrypted under the first key, with the tag over it and `aad` appended."""
        sealed: bytes = self._ciphers()[self._ids[0]][0].encrypt(nonce, data, aad)
        return sealed

    def open(self, kid: bytes, nonce: bytes, sealed: bytes, aad: bytes) -> bytes | None:
        """The plaintext of `sealed` under a key with id `kid`, or None when no such key's tag
        matches (forged, altered, truncated, or sealed under another key)."""
        from cryptography.exceptions import InvalidTag  # noqa: PLC0415 - loaded by _ciphers

        for cipher in self._ciphers().get(kid, ()):
            try:
                data: bytes = cipher.decrypt(nonce, sealed, aad)
            except InvalidTag:
                continue
            return data
        return None

    def receiver_ids(self, name: str, kid: bytes | None = None) -> tuple[bytes, ...]:
        """The receiver ids of robot `name` under the keys with id `kid` (default: the sealing
        key; one id unless two keys' ids collide): a keyed BLAKE2b of the name, never all
        zeros (`NO_RECEIVER`), and empty for a key id the ring does not hold."""
        kid = self._ids[0] if kid is None else kid
        cached = self._receiver_ids.get((kid, name))
        if cached is not None:
            return cached
        if self._receiver_keys is None:
            rkeys: dict[bytes, list[bytes]] = {}
            for i, key in zip(self._ids, self._keys, strict=True):
                rkeys.setdefault(i, []).append(receiver_key(key))
            self._receiver_keys = rkeys
        ids = tuple(
            hashlib.blake2b(name.encode(), key=k, digest_size=RECEIVER_ID_SIZE).digest()
            for k in self._receiver_keys.get(kid, ())
        )
        ids = tuple(NO_RECEIVER[:-1] + b"\1" if r == NO_RECEIVER else r for r in ids)
        if len(self._receiver_ids) >= _RECEIVER_CACHE:
            self._receiver_ids.clear()  # a flood of names cannot grow it without bound
        self._receiver_ids[(kid, name)] = ids
        return ids

    def find(self, kid: bytes) -> bytes | None:
        """The first key of the ring with id `kid`, or None."""
        for i, known in enumerate(self._ids):
            if known == kid:
                return self._keys[i]
        return None

    def with_key(self, key: bytes) -> Keyring:
        """This ring with `key` added last (it opens, it does not seal); the same keys when it
        is in already."""
        return Keyring([*self._keys, key])

    def with_primary(self, kid: bytes) -> Keyring:
        """This ring with the key of id `kid` first (it seals); ConfigError when no key has it."""
        key = self.find(kid)
        if key is None:
            raise ConfigError(f"keyring: no key with id {kid.hex()} (install it first)")
        return Keyring([key, *(k for k in self._keys if k != key)])

    def without(self, kid: bytes) -> Keyring:
        """This ring without the key(s) of id `kid` (the same ring when none has it);
        ConfigError for the sealing key (make another one primary first)."""
        if kid == self._ids[0]:
            raise ConfigError(
                f"keyring: key {kid.hex()} is the primary (it seals): make another key primary "
                "before retiring it"
            )
        return Keyring([k for k, i in zip(self._keys, self._ids, strict=True) if i != kid])

    def to_text(self, comment: str = "") -> str:
        """The ring as a key file (the primary first), with `comment` lines on top."""
        head = "".join(f"# {line}\n" for line in comment.splitlines())
        return head + "".join(format_key(k) + "\n" for k in self._keys)

    @staticmethod
    def generate() -> bytes:
        """A new random 32-byte key."""
        return os.urandom(32)

    format_key = staticmethod(format_key)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str]) -> Keyring:
        """Keys from a file: one per line, hex or base64, `#` comments; the first key seals.

        A line of an even number of hex digits is hex, anything else must be base64 (a 32-byte
        key is 64 chars in hex, 44 chars ending in "=" in base64); "hex:" or "base64:" in front
        of a key says which explicitly.
        """
        try:
            text = Path(path).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as e:
            raise ConfigError(f"{path}: cannot read key file: {e}") from e
        keys: list[bytes] = []
        for lineno, raw in enumerate(text.splitlines(), 1):
            line = raw.split("#", 1)[0].strip()
            if not line:
                continue
            try:
                key = parse_key(line)
            except (ValueError, binascii.Error):
                raise ConfigError(
                    f"{path}:{lineno}: not a hex or base64 key (one key per line, # comments)"
                ) from None
            if len(key) < MIN_KEY_SIZE:
                raise ConfigError(
                    f"{path}:{lineno}: key has {len(key)} bytes, at least {MIN_KEY_SIZE} needed"
                )
            keys.append(key)
        if not keys:
            raise ConfigError(f"{path}: no key in key file")
        return cls(keys)
