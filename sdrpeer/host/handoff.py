"""The host's side of state handoff: the `snapshot` and `restore` commands (docs/protocol.md).

How it works: `snapshot` asks the runner for `on_snapshot()`'s value (sdrpeer.sdk.handoff says in
which states) and encodes it with msgpack; a value msgpack cannot encode, or one over the `max`
bytes the command allows, is refused. The bytes go back as `part` messages right before the reply
(`serve.py` writes them). `restore` takes the bytes its `part`s carried (`Request.blob`), decodes
them (exactly one msgpack value) and hands the value to the runner's `restore`; undecodable bytes
are refused before any callback runs (parts that do not add up never get here: the control
decoder refuses such a `restore`). Every failure raises (CommandError, or
what the runner raised) and becomes `reply ok=false`: none of them ends the host.
"""

from __future__ import annotations

from sdrpeer.control.messages import Snapshot
from sdrpeer.control.parts import decode_value, encode_value
from sdrpeer.errors import HandoffError, PartError
from sdrpeer.sdk import ComponentRunner

__all__ = ["HandoffError", "restore", "snapshot"]


async def snapshot(runner: ComponentRunner, command: Snapshot) -> bytes:
    """The msgpack bytes of the component's state, checked against the command's `max`."""
    value = await runner.snapshot()
    try:
        blob = encode_value(value)
    except PartError as exc:
        raise HandoffError(f"snapshot: on_snapshot returned a value that {exc}") from None
    limit = command.max_bytes
    if limit is not None and len(blob) > limit:
        raise HandoffError(
            f"snapshot: state of {len(blob)} bytes is over the limit of {limit} bytes"
        )
    return blob


async def restore(runner: ComponentRunner, blob: bytes) -> None:
    """Decode the state its parts carried (`blob`) and hand it to the component's on_restore."""
    try:
        value = decode_value(blob)
    except PartError as exc:
        raise HandoffError(f"restore: state is {exc}") from None
    await runner.restore(value)
