"""Data ports: `OutPort` and `InPort` declared on a Component class, one runtime port per instance.

How it works: the class attributes are descriptors; `Component.__init__` asks each for a fresh
runtime object (`OutPortRuntime` / `InPortRuntime`) and the descriptor returns it on attribute
access, so `self.image.write(frame)` touches only that instance's port.

- `OutPortRuntime.write(value)` hands the same object (never copied) to every attached sink's
  `offer(value) -> bool` (False: the sink dropped it) and counts it. The data plane writes the
  sinks (`FrameSink`); a sink may also have `bytes_out` (summed into the counters) and
  `replayed` (frames written again to a new receiver: sdrpeer.dataplane.connection) and
  `async drain()`, which `send()` awaits first: it returns once the sink can take a frame (a
  `full="block"` sink that is full waits; others return at once).
- `InPortRuntime` (sdrpeer.sdk.inport) is what the data plane delivers received frames to.
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from dataclasses import dataclass
from typing import Any, Final, Literal, Protocol, overload

from sdrpeer.sdk.inport import InPortRuntime
from sdrpeer.sdk.policy import ConnectorPolicy
from sdrpeer.sdk.typed import PortTypeError, port_message, type_id_of

__all__ = ["FrameSink", "InPort", "InPortRuntime", "OutPort", "OutPortRuntime", "PortInfo"]


class FrameSink(Protocol):
    """Where an OutPort's frames go (a data-plane connection); see the module doc for extras."""

    def offer(self, value: Any) -> bool:
        """Take one frame (not copied); False if it was dropped."""


@dataclass(frozen=True, slots=True)
class PortInfo:
    """What the host reports about one declared port."""

    name: str
    """The attribute name, used as the port's name in connections."""
    kind: Literal["in", "out"]
    """Direction."""
    doc: str
    """One line for people."""
    policy: ConnectorPolicy | None
    """An InPort's default policy (used for connections that bring none); None for OutPorts."""
    type_id: str | None = None
    """The message type's id (sdrpeer.sdk.typed), None when the port takes any value."""

    def to_map(self) -> dict[str, Any]:
        """A msgpack/JSON-friendly map."""
        out: dict[str, Any] = {"name": self.name, "kind": self.kind, "doc": self.doc}
        if self.policy is not None:
            out["policy"] = self.policy.to_map()
        if self.type_id is not None:
            out["type"] = self.type_id
        return out


_SINK_COUNTERS: Final = (
    "frames_out",
    "bytes_out",
    "replayed",
    "evicted",
    "dropped_remote",
    "overflowed",
)
"""What a data-plane sink counts (`sdrpeer.dataplane.connection.Connection`), summed per port."""


class OutPortRuntime:
    """One component instance's output port: fan-out to the attached sinks."""

    __slots__ = (
        "_drainers",
        "_encode",
        "_gone",
        "_sinks",
        "_type",
        "doc",
        "dropped",
        "frames_out",
        "name",
        "type_id",
    )

    def __init__(self, name: str, doc: str = "", port_type: type | None = None) -> None:
        self.name = name
        self.doc = doc
        info = port_message(port_type)
        self._type = port_type
        self._encode = None if info is None else info.encode
        self.type_id = None if info is None else info.type_id
        """The message type's id (None: any value)."""
        self.frames_out = 0
        self.dropped = 0
        """Values a sink refused (its policy's drop or skip, or full with block and written
        without waiting for room)."""
        self._sinks: tuple[FrameSink, ...] = ()
        self._drainers: tuple[Callable[[], Awaitable[Any]], ...] = ()
        self._gone = dict.fromkeys(_SINK_COUNTERS, 0)  # counters of sinks already detached

    def write(self, value: Any) -> None:
        """Hand `value` to every sink (hot path: no copy, no await). A typed port takes only
        its type and sends its fields (sdrpeer.sdk.typed)."""
        if self._encode is not None:
            if type(value) is not self._type:
                raise PortTypeError(
                    f"out-port {self.name!r} sends {self.type_id}, not {type(value).__name__}"
                )
            value = self._encode(value)
        self.frames_out += 1
        for sink in self._sinks:
            if not sink.offer(value):
                self.dropped += 1

    async def send(self, value: Any) -> None:
        """Wait until every sink can take a frame (backpressure), then `write(value)`."""
        for drain in self._drainers:
            await drain()
        self.write(value)

    def attach(self, sink: FrameSink) -> None:
        """Start handing frames to `sink` (attaching the same sink twice is a no-op)."""
        if sink not in self._sinks:
            self._sinks = (*self._sinks, sink)
            self._rebuild()

    def detach(self, sink: FrameSink) -> None:
        """Stop handing frames to `sink`; its counts stay in the port's counters."""
        if sink in self._sinks:
            self._sinks = tuple(s for s in self._sinks if s is not sink)
            for key in _SINK_COUNTERS:
                self._gone[key] += int(getattr(sink, key, 0))
            self._rebuild()

    @property
    def sinks(self) -> tuple[FrameSink, ...]:
        """The attached sinks."""
        return self._sinks

    def counters(self) -> dict[str, int]:
        """The protocol's port counters (input-side ones are zero). `frames_out`: values the
        component wrote (whether or not a connection carried them: a standalone host's output
        rate); `frames_sent` and `bytes_out`: frames its connections handed to a socket, summed
        over the connections (a frame sent to two receivers counts twice). `dropped`: values the
        sending side lost to its connections' policies (refused, or queued and evicted);
        `dropped_remote`: frames the receiving InPorts discarded on a full buffer, as their
        acknowledgements told; `overflowed`: frames lost to a full buffer at either end (what
        the agent warns about: `new` and `skip` thin out by design)."""
        total = {
            key: self._gone[key] + sum(int(getattr(s, key, 0)) for s in self._sinks)
            for key in _SINK_COUNTERS
        }
        return {
            "frames_in": 0,
            "bytes_in": 0,
            "frames_out": self.frames_out,
            "frames_sent": total["frames_out"],
            "bytes_out": total["bytes_out"],
            "dropped": self.dropped + total["evicted"],
            "dropped_remote": total["dropped_remote"],
            "overflowed": total["overflowed"],
            "lost": 0,
            "refused": 0,
            "replayed": total["replayed"],
        }

    def _rebuild(self) -> None:
        drains = (getattr(s, "drain", None) for s in self._sinks)
        self._drainers = tuple(d for d in drains if callable(d))


class OutPort:
    """Declare an output port on a Component class."""

    kind: Final = "out"

    def __init__(self, doc: str = "", *, type: type | None = None) -> None:
        self.doc = doc
        self.name = "<unbound>"
        self.type = type
        """The message type the port sends (a @message dataclass), None: any value."""
        self.type_id = type_id_of(type)

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @overload
    def __get__(self, instance: None, owner: type | None = None) -> OutPort: ...
    @overload
    def __get__(self, instance: object, owner: type | None = None) -> OutPortRuntime: ...
    def __get__(self, instance: object | None, owner: type | None = None) -> Any:
        if instance is None:
            return self
        return instance._ports[self.name]  # type: ignore[attr-defined]

    def make(self) -> OutPortRuntime:
        """A fresh runtime port for one instance."""
        return OutPortRuntime(self.name, self.doc, self.type)

    def info(self) -> PortInfo:
        """This port's metadata."""
        return PortInfo(self.name, "out", self.doc, None, self.type_id)


class InPort:
    """Declare an input port on a Component class, with its default connector policy."""

    kind: Final = "in"

    def __init__(
        self,
        doc: str = "",
        policy: ConnectorPolicy | dict[str, Any] | None = None,
        *,
        type: type | None = None,
    ) -> None:
        self.doc = doc
        self.name = "<unbound>"
        self.type = type
        """The message type the port takes (a @message dataclass), None: any value."""
        self.type_id = type_id_of(type)
        if isinstance(policy, dict):
            policy = ConnectorPolicy.from_map(policy)
        self.policy = policy or ConnectorPolicy()

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    @overload
    def __get__(self, instance: None, owner: type | None = None) -> InPort: ...
    @overload
    def __get__(self, instance: object, owner: type | None = None) -> InPortRuntime: ...
    def __get__(self, instance: object | None, owner: type | None = None) -> Any:
        if instance is None:
            return self
        return instance._ports[self.name]  # type: ignore[attr-defined]

    def make(self) -> InPortRuntime:
        """A fresh runtime port for one instance."""
        return InPortRuntime(self.name, self.policy, self.doc, self.type)

    def info(self) -> PortInfo:
        """This port's metadata."""
        return PortInfo(self.name, "in", self.doc, self.policy, self.type_id)
