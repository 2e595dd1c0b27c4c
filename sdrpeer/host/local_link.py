"""A connection from one of a host's OutPorts to one of its own InPorts, handed over in process.

How it works: when a `connect` names the host's own data address (a composite's member feeding
another member, sdrpeer.sdk.composite), `HostedInstance` attaches a `LocalLink` instead of a
data-plane `Connection`: `offer` calls the InPort's `deliver` at once, with its own sequence
numbers, so a value a member writes is in the next member's queue before that member's
`on_execute` runs in the same period (OpenRTM's in-process connectors of a composite). The
receive side of the connection's policy applies as it would over a socket (`buffer` and `full`
over the port's declared policy, `full: block` left out: nothing acknowledges), and so do
`push: new` and `push: skip`, which the InPort applies per connection. Nothing is sent or
encrypted, and an untyped value is handed over as it is; a typed OutPort's wire form (a tuple of
fields, or a `WireBlob` carrying an image) is made what a socket would deliver (msgpack arrays
as lists), so a typed InPort takes it exactly as from another host. There is nothing to
repoint (both ends live and move together), and `close` forgets the connection at the InPort
(frames already queued stay readable).
"""

from __future__ import annotations

from typing import Any

import msgpack

from sdrpeer.sdk import InPortRuntime
from sdrpeer.sdk.typed import WireBlob


class LocalLink:
    """An OutPort's sink delivering straight into an InPort of the same host."""

    def __init__(self, conn_id: str, port: InPortRuntime, given: dict[str, Any]) -> None:
        self.conn_id = conn_id
        self.port = port
        policy = port.connection_policy(given, acked=False)
        sender = {k: v for k, v in given.items() if k in ("push", "skip")}
        port.connect(conn_id, policy.merged(sender) if sender else policy)
        self.frames_out = 0
        """Frames handed to the InPort (the protocol's `frames_sent` of the OutPort)."""
        self.bytes_out = 0
        """Always 0: nothing is encoded."""

    def offer(self, value: Any) -> bool:
        """Deliver one value now (the InPort's policy may still drop it: its counters say)."""
        self.frames_out += 1
        if type(value) is tuple:  # a typed port's fields (sdrpeer.sdk.typed)
            value = msgpack.unpackb(msgpack.packb(value), strict_map_key=False)
        elif type(value) is WireBlob:
            value = msgpack.unpackb(value.prefix + value.data, strict_map_key=False)
        self.port.deliver(value, self.frames_out, self.conn_id)
        return True

    def close(self) -> None:
        """Forget the connection at the InPort."""
        self.port.disconnect(self.conn_id)
