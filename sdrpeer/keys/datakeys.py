"""The data keys hosts authenticate their data connections with (sdrpeer.dataplane.auth).

How it works: one data key per cluster key, derived one way by the agent
(`sdrpeer.keys.derive.data_keys`: BLAKE2b with a fixed personalisation), so a host never holds a
cluster key and a data key cannot sign gossip. This module imports nothing heavy: hosts read
their keys with it. The
agent hands them to each host in SDRPEER_DATA_KEYS (hex, comma-separated, the signing key first)
and, when its keys rotate, to running hosts with the `data_keys` command.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Final

__all__ = ["ENV", "keys_from_env", "keys_to_env"]

ENV: Final = "SDRPEER_DATA_KEYS"


def keys_to_env(keys: Iterable[bytes]) -> str:
    """The SDRPEER_DATA_KEYS value."""
    return ",".join(k.hex() for k in keys)


def keys_from_env(value: str | None) -> list[bytes]:
    """The keys of a SDRPEER_DATA_KEYS value; ValueError naming a bad one."""
    keys = []
    for i, part in enumerate((value or "").split(",")):
        if not part.strip():
            continue
        try:
            key = bytes.fromhex(part.strip())
        except ValueError:
            raise ValueError(f"{ENV}: key {i + 1} is not hex") from None
        if not 16 <= len(key) <= 64:
            raise ValueError(f"{ENV}: key {i + 1} must be 16 to 64 bytes")
        keys.append(key)
    return keys
