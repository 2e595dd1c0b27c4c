"""The host's side of state handoff: the `snapshot` and `restore` commands (docs/protocol.md).

How it works: `snapshot` asks the runner for `on_snapshot()`'s value (sdrpeer.sdk.handoff says in
which states) and encodes it with msgpack; a value msgpack cannot encode, or one over the `max`
bytes the command allows, is refused. The bytes go back as `part` messages right before the reply
(`serve.py` writes them). `restore` takes the bytes its `part`s carried (`Command.blob`), decodes
them (exactly one msgpack value) and hands the value to the runner's `restore`; incomplete or
undecodable bytes are refused before any callback runs. Every failure raises (CommandError, or
what the runner raised) and becomes `reply ok=false`: none of them ends the host.
"""

from __future__ import annotations

from sdrpeer.control.parts import decode_value, encode_value
from sdrpeer.errors import HandoffError, PartError
from sdrpeer.host.control import Command
from sdrpeer.sdk import ComponentRunner

__all__ = ["HandoffError", "restore", "snapshot"]


async def snapshot(runner: ComponentRunner, command: Command) -> bytes:
    """The msgpack bytes of the component's state, checked against the command's `max`."""
    value = await runner.snapshot()
    try:
        blob = encode_value(value)
    except PartError as exc:
        raise HandoffError(f"snapshot: on_snapshot returned a value that {exc}") from None
    limit = command.msg.get("max")
    if type(limit) is int and len(blob) > limit:
        raise HandoffError(
            f"snapshot: state of {len(blob)} bytes is over the limit of {limit} bytes"
        )
    return blob


async def restore(runner: ComponentRunner, command: Command) -> None:
    """Decode the state its parts carried and hand it to the component's on_restore."""
    if command.blob is None:
        why = command.blob_error or "no 'size': the state comes in parts (docs/protocol.md)"
        raise HandoffError(f"restore: {why}")
    try:
        value = decode_value(command.blob)
    except PartError as exc:
        raise HandoffError(f"restore: state is {exc}") from None
    await runner.restore(value)
