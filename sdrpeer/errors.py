"""One error hierarchy for everything a user or a peer can get wrong.

Our own mistakes are ordinary exceptions (bugs); these are the errors that carry a message meant
for a person: what was wrong and where. Every one is defined here, except the component SDK's
own family (`sdrpeer.sdk.errors`: LifecycleError, CallbackError, ParamError, PortError, NoData,
ComponentError), which component authors import from the SDK.

```
SdrpeerError
├── ConfigError                a file, flag or robot file is wrong (file, line, field)
│   ├── ScenarioError, SpecError, SystemFileError, ProfileFileError
│   └── LauncherError, LaunchRefused
├── MalformedError             bytes from a peer that are not accepted; `reason` is the counter
│   ├── WireError              a gossip datagram
│   ├── RecordError            a robot record, vitals, trap or election state
│   └── FrameError             a data-stream hello, reply or frame
├── ControlError               the control channel between an agent and a host
│   ├── ProtocolError          the peer broke the channel's contract (the channel closes)
│   ├── PartError              the parts of a transfer do not add up
│   ├── CommandError           agent side: a command did not succeed (refused/timeout/closed)
│   │   └── StateError         a state cannot be handed over
│   └── CommandRefused         host side: a command cannot be carried out as given
├── ApiError                   a call to an agent's HTTP API failed
├── NotAllocator               this robot is not the allocator
├── MoveError                  a planned move cannot be asked for
├── LoadError, HandoffError    a host cannot load its target / hand over a state
├── RtcError                   a hosted OpenRTM RTC did not do what its lifecycle call asked
├── RtcDataError               a value does not fit an RTC DataPort's OpenRTM data type
├── ProfileError               a component could not be profiled
└── ElectionError              the election core tried a move its table forbids
```

A message echoes what it refuses, so a 200 kB name would make a 200 kB message: every
SdrpeerError's message goes through `clip`, which cuts each quoted string or unbroken run of
characters longer than SHOWN_LIMIT to its first SHOWN_HEAD characters and says how long it was
(`got 'NNNN...N'... (200,224 characters)`); `shown(value)` is the same for one value (a repr),
for messages that are not errors yet (a parser's ValueError, an API's 400).
"""

from __future__ import annotations

import re
from collections.abc import Sequence

SHOWN_LIMIT = 200
"""The longest piece of input an error message shows whole (characters)."""
SHOWN_HEAD = 60
"""How much of a longer one it shows, followed by `... (N characters)`."""

_QUOTED = re.compile(r"""(?<!\w)(?:'(?:[^'\\\n]|\\.)*'|"(?:[^"\\\n]|\\.)*")""")
"""A quoted string as repr() writes it (an apostrophe inside a word opens none)."""
_LONG_RUN = re.compile(rf"[^\s'\"]{{{SHOWN_LIMIT + 1},}}")
"""A run of characters with no space or quote longer than SHOWN_LIMIT."""


def _cut(text: str) -> str:
    return f"{text[:SHOWN_HEAD]}... ({len(text):,} characters)"


def shown(value: object) -> str:
    """`repr(value)` for a message, or when longer than SHOWN_LIMIT characters its first
    SHOWN_HEAD and its length: `'NNNN...N'... (200,224 characters)`."""
    text = value if isinstance(value, str) else repr(value)
    if len(text) <= SHOWN_LIMIT:
        return repr(value)
    if isinstance(value, str):
        return f"{text[:SHOWN_HEAD]!r}... ({len(text):,} characters)"
    return _cut(text)


def clip(message: str) -> str:
    """`message` with every quoted string, and every run without a space, longer than
    SHOWN_LIMIT characters cut as `shown` cuts a value (short messages come back as they are)."""
    if len(message) <= SHOWN_LIMIT:
        return message

    def quoted(match: re.Match[str]) -> str:
        whole = match.group(0)
        body = whole[1:-1]
        if len(body) <= SHOWN_LIMIT:
            return whole
        return f"{whole[0]}{body[:SHOWN_HEAD]}{whole[0]}... ({len(body):,} characters)"

    return _LONG_RUN.sub(lambda m: _cut(m.group(0)), _QUOTED.sub(quoted, message))


class SdrpeerError(Exception):
    """Base of every error sdrpeer raises on purpose; its message is `clip`ped."""

    def __init__(self, *args: object) -> None:
        super().__init__(*(clip(a) if isinstance(a, str) else a for a in args))


# --- configuration ----------------------------------------------------------------------------


class ConfigError(SdrpeerError):
    """A configuration file, flag or robot file is wrong (the message names file, line, field)."""


class ScenarioError(ConfigError):
    """A scenario file is wrong."""


class SpecError(ConfigError):
    """An instance or connection spec is wrong; `field` is the dotted name of the culprit."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"field '{field}': {message}")
        self.field = field


class SystemFileError(ConfigError):
    """A system file is wrong; `.problems` lists every problem (`file:line: field 'x': ...`)."""

    def __init__(self, message: str, problems: Sequence[str] | None = None) -> None:
        super().__init__(message)
        self.problems: list[str] = (
            [clip(p) for p in problems] if problems is not None else [str(self)]
        )

    @classmethod
    def collect(cls, name: str, problems: Sequence[str]) -> SystemFileError:
        """One error for several problems: a count line, then one problem per line."""
        if len(problems) == 1:
            return cls(problems[0], problems)
        head = f"{name}: {len(problems)} problems"
        return cls("\n".join([head, *problems]), problems)


class ProfileFileError(ConfigError, ValueError):
    """A profile file a system file names is missing, unreadable or lacks a figure we need."""


class LauncherError(ConfigError):
    """An instance names an unknown launcher or gives it a target it cannot use."""


class LaunchRefused(ConfigError):
    """A spec this robot's launch policy does not let run (the API answers 403)."""


# --- bytes from peers -------------------------------------------------------------------------


class MalformedError(SdrpeerError):
    """Bytes a peer sent that are not accepted; `reason` is the counter it is filed under."""

    def __init__(self, reason: str, detail: str = "") -> None:
        super().__init__(f"{reason}: {detail}" if detail else reason)
        self.reason = reason
        self.detail = detail


class WireError(MalformedError):
    """A gossip datagram was not accepted. `sender_behind`: it was authenticated (its sender holds
    a cluster key), refused as older than the freshness window and newer than anything its
    sender sent before: the sender's cluster time is behind ours, not an attack (the shell tells
    it so). `sender`: the robot that sent it, when its body was read ("" before)."""

    def __init__(
        self, reason: str, detail: str = "", *, sender_behind: bool = False, sender: str = ""
    ) -> None:
        super().__init__(reason, detail)
        self.sender_behind = sender_behind
        self.sender = sender


class RecordError(MalformedError):
    """A robot record, its vitals, a trap or an election state does not decode (`malformed`)."""


class FrameError(MalformedError):
    """A hello, reply or frame could not be accepted; `reason` is oversized or malformed."""


# --- the control channel ----------------------------------------------------------------------


class ControlError(SdrpeerError):
    """Something went wrong on the control channel between an agent and a component host."""


class ProtocolError(ControlError):
    """The peer sent something the control channel contract forbids; the channel is closed."""


class PartError(ControlError):
    """The parts of a transfer do not add up (missing, too many bytes, or over the limit)."""


class CommandError(ControlError):
    """The agent's side: a command did not succeed; `reason` is refused, timeout or closed."""

    def __init__(self, command: str, reason: str, detail: str = "") -> None:
        super().__init__(f"{command}: {reason}" + (f" ({detail})" if detail else ""))
        self.command = command
        self.reason = reason
        self.detail = detail


class StateError(CommandError):
    """A state cannot be handed over: too big, or not one msgpack value."""

    def __init__(self, command: str, detail: str) -> None:
        super().__init__(command, "refused", detail)


class CommandRefused(ControlError):
    """The host's side: a command cannot be carried out as given (the message names the field)."""


# --- everything else --------------------------------------------------------------------------


class ApiError(SdrpeerError):
    """A call to an agent's HTTP API failed (the message says which agent and why)."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status
        """The HTTP status the agent answered with, None when it could not be reached."""


class PortToolError(SdrpeerError):
    """A port tool request (`sdrpeer port ...`) cannot be done as asked: an unknown instance or
    port, a type mismatch, a value that does not fit the port's type (the message says which)."""

    def __init__(self, message: str, status: int = 400) -> None:
        super().__init__(message)
        self.status = status
        """The HTTP status the API answers it with (400 bad value, 404 unknown, 409 refused)."""


class NotAllocator(SdrpeerError):
    """This robot is not the allocator; `leader` is the one it believes in (or None)."""

    def __init__(self, leader: str | None) -> None:
        super().__init__(leader)
        self.leader = leader


class MoveError(SdrpeerError, ValueError):
    """The move cannot be asked for (no system, unknown component, bad destination)."""


class LoadError(SdrpeerError):
    """The host's target could not be loaded (the message names the target and the reason)."""


class RtcError(SdrpeerError):
    """A hosted OpenRTM RTC did not do what its lifecycle call asked (its onExecute returned an
    error, it is in ERROR_STATE, or its execution context refused): the sdrpeer component's ERROR
    (sdrpeer.openrtm.component)."""


class RtcDataError(SdrpeerError, ValueError):
    """A value does not fit the OpenRTM data type it should be written as (the message names
    the type and the field)."""


class HandoffError(SdrpeerError):
    """A snapshot or restore command cannot be carried out (the message says why)."""


class ProfileError(SdrpeerError):
    """The component could not be profiled (did not start, went to ERROR, ...)."""


class ElectionError(SdrpeerError):
    """The election core tried a move its table does not allow (a bug in the core)."""
