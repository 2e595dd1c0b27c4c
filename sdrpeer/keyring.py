"""Cluster keys: a keyring whose first key signs and every key verifies (rotation without
downtime), with the key file format.

How it works: a key is at least 16 random bytes, identified on the wire by the first 4 bytes of
its SHA-256 (the key id). `Keyring.sign` uses the first key; `Keyring.verify` looks the key up by
id and compares HMAC-SHA256 in constant time. Rotation: add the new key second everywhere (both
verify), move it first everywhere (it signs, the old one still verifies), then remove the old.
Key files hold one key a line, hex or base64 (a `hex:`/`base64:` prefix says which), `#` comments.
"""

from __future__ import annotations

import base64
import binascii
import hashlib
import hmac
import os
import re
from collections.abc import Sequence
from pathlib import Path

from sdrpeer.errors import ConfigError

KEY_ID_SIZE = 4
MAC_SIZE = 32
INSECURE_KEY_ID = b"\0" * KEY_ID_SIZE
MIN_KEY_SIZE = 16
_HEX = re.compile(r"(?:[0-9a-fA-F]{2})+")


def key_id(key: bytes) -> bytes:
    """The 4-byte id of `key` sent in every datagram it signs: sha256(key)[:4]."""
    return hashlib.sha256(key).digest()[:KEY_ID_SIZE]


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
    """Cluster keys: the first signs, every key verifies (so keys rotate without downtime)."""

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
        self._macs: dict[bytes, list[hmac.HMAC]] = {}
        for kid, key in zip(self._ids, self._keys, strict=True):
            self._macs.setdefault(kid, []).append(hmac.new(key, digestmod=hashlib.sha256))
        self._signer = self._macs[self._ids[0]][0]

    @property
    def signing_key(self) -> bytes:
        """The key that signs outgoing datagrams (the first one)."""
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
        return kid in self._macs

    def sign(self, data: bytes) -> tuple[bytes, bytes]:
        """(key id, HMAC-SHA256 of `data`) under the signing key."""
        mac = self._signer.copy()
        mac.update(data)
        return self._ids[0], mac.digest()

    def verify(self, kid: bytes, data: bytes, mac: bytes) -> bool:
        """Whether `mac` is the HMAC of `data` under a key with id `kid` (constant-time compare)."""
        ok = False
        for base in self._macs.get(kid, ()):
            h = base.copy()
            h.update(data)
            ok |= hmac.compare_digest(h.digest(), mac)
        return ok

    @staticmethod
    def generate() -> bytes:
        """A new random 32-byte key."""
        return os.urandom(32)

    format_key = staticmethod(format_key)

    @classmethod
    def from_file(cls, path: str | os.PathLike[str]) -> Keyring:
        """Keys from a file: one per line, hex or base64, `#` comments; the first key signs.

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
