"""The agent's side of state handoff: take a running instance's state, give it to another one.

How it works: `take_snapshot` fetches `Snapshot` with `max` (the size limit, SupervisorConfig's
`max_state`, 16 MiB by default), accepting that many bytes of `part`s back; the host refuses a
bigger state itself, and the channel refuses parts past the limit. The bytes are decoded (exactly
one msgpack value). `give_state` encodes the value, refuses it before sending when msgpack cannot
encode it or it is over the limit, and sends `Restore` with the bytes in parts. Either failure is a
`StateError`, a `CommandError` saying "refused" and why; what the host refuses arrives as
`CommandError` "refused" with the host's words.
"""

from __future__ import annotations

from typing import Any, Final, Protocol

from sdrpeer.control.messages import Command, Reply, Restore, Snapshot
from sdrpeer.control.parts import decode_value, encode_value
from sdrpeer.errors import PartError, StateError

__all__ = ["MAX_STATE", "StateError", "give_state", "take_snapshot"]

MAX_STATE: Final = 16 << 20
"""The default size limit of a state, in bytes of msgpack."""


class Channel(Protocol):
    """What state handoff needs of a control channel (agent_side.ControlChannel has it)."""

    async def command(self, cmd: Command, *, blob: bytes | None = None) -> Reply:
        """Send `cmd` (with `blob` in parts), await its reply."""

    async def fetch(self, cmd: Command, limit: int) -> bytes:
        """Send `cmd`, return the up to `limit` bytes of parts its reply brings."""


async def take_snapshot(channel: Channel, limit: int = MAX_STATE) -> Any:
    """The state of the instance `channel` talks to (None if its component keeps none)."""
    blob = await channel.fetch(Snapshot(limit), limit)
    try:
        return decode_value(blob)
    except PartError as e:
        raise StateError("snapshot", f"the host sent a state that is {e}") from None


async def give_state(channel: Channel, state: Any, limit: int = MAX_STATE) -> None:
    """Hand `state` to the instance's `on_restore`."""
    try:
        blob = encode_value(state)
    except PartError as e:
        raise StateError("restore", f"the state: {e}") from None
    if len(blob) > limit:
        raise StateError("restore", f"state of {len(blob)} bytes is over the limit of {limit}")
    await channel.command(Restore(len(blob)), blob=blob)
