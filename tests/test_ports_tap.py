"""A tap's receiver listens on a Unix socket in a private directory only (no TCP port another
local process could push frames into), and leaves nothing behind when it closes."""

from __future__ import annotations

from pathlib import Path

from sdrpeer.keys.derive import data_key
from sdrpeer.ports.tap import Tap


async def test_a_tap_listens_only_on_its_private_unix_socket() -> None:
    tap = Tap(2, (data_key(b"\x05" * 32),))
    await tap.start()
    try:
        assert set(tap.server.addresses) == {"unix"}
        path = Path(tap.address.removeprefix("unix://"))
        assert path.is_socket()  # noqa: ASYNC240 - a test reading its own temporary files
        assert path.parent.stat().st_mode & 0o077 == 0
    finally:
        await tap.close()
    assert not path.parent.exists()
