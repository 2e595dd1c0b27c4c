"""The control channel's messages (docs/protocol.md, section 1): one frozen dataclass each.

How it works: a message is a plain value; its class attribute `T` is its `"t"` on the wire.
Commands (agent -> host) carry no id: the id is the channel's business, and `codec.encode`
writes it right after `"t"`, as the protocol has it. Reports (host -> agent) are written as they
are; `Reply` carries the id of the command it answers, `Part` the id (`of`) of the message its
bytes belong to (it travels both ways). A field's wire key is its name unless its metadata says
`wire` (`Conn.in_port` is `"in"`); a field marked `omit` is left off the wire when it is None
(the key is absent), every other one is always written (None as nil); `choices` are the only
values a field may take. `codec.py` is the only code
that turns these into maps and back, checking every field's type. Kept light: the host imports it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, ClassVar, Final

from sdrpeer.vocabulary import LifecycleState

__all__ = [
    "COMMANDS",
    "LIFECYCLE",
    "PROTOCOL",
    "REPORTS",
    "Activate",
    "Command",
    "Conn",
    "Connect",
    "DataKeys",
    "Deactivate",
    "Disconnect",
    "Exit",
    "Fault",
    "Heartbeat",
    "Hello",
    "Part",
    "Refused",
    "Reply",
    "Repoint",
    "Report",
    "Reset",
    "Restore",
    "SetParams",
    "Snapshot",
    "State",
    "Step",
]

PROTOCOL: Final = 1
"""Version of the control channel, sent in `hello`."""
LIFECYCLE: Final = tuple(LifecycleState)
"""The states a `state` report may name."""

_OMIT: Final = {"omit": True}


def _wire(name: str) -> dict[str, Any]:
    return {"wire": name}


# -- agent -> host: commands ----------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Activate:
    """INACTIVE -> ACTIVE (`on_activated`)."""

    T: ClassVar[str] = "activate"


@dataclass(frozen=True, slots=True)
class Deactivate:
    """ACTIVE -> INACTIVE (`on_deactivated`)."""

    T: ClassVar[str] = "deactivate"


@dataclass(frozen=True, slots=True)
class Reset:
    """ERROR -> INACTIVE (`on_reset`)."""

    T: ClassVar[str] = "reset"


@dataclass(frozen=True, slots=True)
class SetParams:
    """Typed parameters changed while running."""

    T: ClassVar[str] = "set_params"
    params: dict[str, Any]
    """Parameter name -> new value (the component's declared types check the values)."""


@dataclass(frozen=True, slots=True)
class Conn:
    """A data connection from one of the host's OutPorts (the `conn` map of `connect`)."""

    id: str
    """The connection's id (what `disconnect` and `repoint` name)."""
    out_port: str = field(metadata=_wire("out"))
    """The sending OutPort."""
    to: str
    """The receiver's data address: `tcp://HOST:PORT` or `unix:///path`."""
    in_port: str = field(metadata=_wire("in"))
    """The InPort on the receiving host."""
    policy: dict[str, Any] | None = field(default=None, metadata=_OMIT)
    """The connector policy map (push, buffer, full, skip); None: absent, the defaults."""


@dataclass(frozen=True, slots=True)
class Connect:
    """Open a data stream from one of the host's OutPorts."""

    T: ClassVar[str] = "connect"
    conn: Conn
    """The connection."""


@dataclass(frozen=True, slots=True)
class Disconnect:
    """Close a data stream."""

    T: ClassVar[str] = "disconnect"
    conn_id: str
    """The connection's id."""


@dataclass(frozen=True, slots=True)
class Repoint:
    """Keep the connection, send its next frames to a new address."""

    T: ClassVar[str] = "repoint"
    conn_id: str
    """The connection's id."""
    to: str
    """The new data address."""


@dataclass(frozen=True, slots=True)
class DataKeys:
    """The data keys from now on (the agent's keys rotated)."""

    T: ClassVar[str] = "data_keys"
    keys: tuple[str, ...]
    """The keys, hex, the signing one first."""


@dataclass(frozen=True, slots=True)
class Exit:
    """Finalize and exit 0."""

    T: ClassVar[str] = "exit"
    timeout: float | None = field(default=None, metadata=_OMIT)
    """Seconds finalizing may take (None: the host's default)."""


@dataclass(frozen=True, slots=True)
class Snapshot:
    """The component's state back in `part`s before the reply, which says `size`."""

    T: ClassVar[str] = "snapshot"
    max_bytes: int | None = field(default=None, metadata={"wire": "max", "omit": True})
    """The most bytes of msgpack the state may take (None: the host's own limit)."""


@dataclass(frozen=True, slots=True)
class Step:
    """Run `n` executions of a `Stepped` execution context now (refused for any other)."""

    T: ClassVar[str] = "step"
    n: int = 1
    """How many (>= 1)."""


@dataclass(frozen=True, slots=True)
class Restore:
    """Hand the state its `part`s carried (right before it) to `on_restore`."""

    T: ClassVar[str] = "restore"
    size: int
    """The total bytes of those parts."""


Command = (
    Activate
    | Deactivate
    | Reset
    | SetParams
    | Connect
    | Disconnect
    | Repoint
    | DataKeys
    | Exit
    | Snapshot
    | Restore
    | Step
)
"""Any command."""
COMMANDS: Final[tuple[type[Command], ...]] = (
    Activate,
    Deactivate,
    Reset,
    SetParams,
    Connect,
    Disconnect,
    Repoint,
    DataKeys,
    Exit,
    Snapshot,
    Restore,
    Step,
)


# -- host -> agent: reports -----------------------------------------------------------------------


@dataclass(frozen=True, slots=True, kw_only=True)
class Hello:
    """The first report: who the host is and where its data server listens."""

    T: ClassVar[str] = "hello"
    protocol: int = field(default=PROTOCOL, metadata={"choices": (PROTOCOL,)})
    """The protocol version (only 1 is spoken)."""
    pid: int
    """The host's process id."""
    component: str
    """The component's class name."""
    ports: dict[str, list[str]]
    """`{"in": [names], "out": [names]}`."""
    params: dict[str, Any]
    """Parameter name -> current value."""
    data: dict[str, str]
    """The data server's addresses: `{"tcp": "HOST:PORT", "unix": "/path"}`."""
    services: dict[str, dict[str, Any]] | None = field(default=None, metadata=_OMIT)
    """Service ports by name (sdrpeer.sdk.services): `{"role": "provides" | "requires",
    "interface": id, "methods": [names]}`; absent when the component declares none."""


@dataclass(frozen=True, slots=True)
class State:
    """A lifecycle change, sent at once."""

    T: ClassVar[str] = "state"
    state: str = field(metadata={"choices": LIFECYCLE})
    """One of LIFECYCLE."""
    ts: float
    """When (unix seconds, the host's clock)."""
    error: str | None = None
    """What went wrong (ERROR), else None."""
    fault: str | None = field(default=None, metadata=_OMIT)
    """The kind of the fault that caused this ERROR, if one did."""


@dataclass(frozen=True, slots=True)
class Reply:
    """The answer to command `id`."""

    T: ClassVar[str] = "reply"
    id: int
    """The command's id."""
    ok: bool
    """Whether it was carried out."""
    error: str | None = None
    """Why not (None when ok)."""
    size: int | None = field(default=None, metadata=_OMIT)
    """The total bytes of the `part`s sent right before (None: no value came back)."""


@dataclass(frozen=True, slots=True)
class Heartbeat:
    """The periodic liveness report, every 0.5 s."""

    T: ClassVar[str] = "heartbeat"
    ts: float
    """When (unix seconds, the host's clock)."""
    ports: dict[str, dict[str, int]]
    """Port name -> counters (frames_in, bytes_in, frames_out, bytes_out, dropped, ...)."""
    data: dict[str, int] | None = field(default=None, metadata=_OMIT)
    """The host's data server: accepted, rejected, refused_auth, deliver_error, shm, acked
    (docs/protocol.md; left out when there is none)."""
    endpoints: dict[str, list[str]] | None = field(default=None, metadata=_OMIT)
    """A hosted ROS 2 node's topics and services (sdrpeer.ros2.node): name -> [direction, ROS
    type], direction `publishes`, `subscribes` or `serves`; their counters are in `ports` under
    the same names (left out for other hosts)."""


@dataclass(frozen=True, slots=True)
class Fault:
    """A fault the component reported, sent at once."""

    T: ClassVar[str] = "fault"
    kind: str
    """hardware_failure, abnormal_behaviour, emergency_stop (or what a foreign host sent)."""
    detail: str
    """The component's words."""
    ts: float | None = None
    """When (unix seconds, the host's clock)."""


@dataclass(frozen=True, slots=True)
class Refused:
    """A receiver refused one of our outgoing connections (sent at once the first time, then
    at most once per 30 s per connection while it goes on), or took it again after refusals
    (`error` None)."""

    T: ClassVar[str] = "refused"
    conn: str
    """The connection's id."""
    from_: str = field(metadata=_wire("from"))
    """The sending `instance.port` (or service port)."""
    to: str
    """The receiver's address it dialled."""
    in_port: str = field(metadata=_wire("in"))
    """The receiving port it named."""
    error: str | None
    """Why it was refused (the receiver's error, or our own check of its answer); None: the
    connection got through again."""
    count: int
    """Refusals since the previous `refused` report of this connection (this one included)."""
    ts: float
    """When (unix seconds, the host's clock)."""


Report = Hello | State | Reply | Heartbeat | Fault | Refused
"""Any report."""
REPORTS: Final[tuple[type[Report], ...]] = (Hello, State, Reply, Heartbeat, Fault, Refused)


# -- both ways -------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Part:
    """A piece of a big value, right before the message it belongs to (control/parts.py)."""

    T: ClassVar[str] = "part"
    of: int
    """The id of that message (a `restore` command, or the command a `reply` answers)."""
    data: bytes
    """The piece."""
