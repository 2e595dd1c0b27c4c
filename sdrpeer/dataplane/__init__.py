"""The data plane: msgpack streams from OutPorts to InPorts (docs/protocol.md section 2).

`Connection` is the sending side (an OutPort's sink; `link` is one of its sockets), `DataServer`
the receiving side (one per host), `frames` the codec both share, `pending` the sender's policy
queue, `writer`/`reader` the two ends' buffers, `shm` the shared-memory ring big values take
between two processes on one machine, `service` the service bindings (a consumer's calls to a
provided service port, over the same listener and handshake).
"""

from sdrpeer.dataplane.connection import Connection
from sdrpeer.dataplane.frames import DEFAULT_MAX_FRAME, FrameDecoder
from sdrpeer.dataplane.pending import PendingQueue, PolicyLike
from sdrpeer.dataplane.port_api import InPortLike
from sdrpeer.dataplane.server import DataServer
from sdrpeer.errors import FrameError

__all__ = [
    "DEFAULT_MAX_FRAME",
    "Connection",
    "DataServer",
    "FrameDecoder",
    "FrameError",
    "InPortLike",
    "PendingQueue",
    "PolicyLike",
]
