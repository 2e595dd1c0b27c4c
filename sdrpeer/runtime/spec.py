"""What an agent is asked to run: instance and connection specs, validated, with a JSON form.

How it works: `InstanceSpec.from_json(doc, where)` checks every field and raises `SpecError`
naming the dotted field (`instances[1].connections[0].policy.buffer`); the dataclasses are frozen
and hashable, so the reconciler can compare a running instance's spec with the desired one.
`to_json` is the inverse (`from_json(to_json(s)) == s`). A connection goes from one of this
instance's OutPorts to `to_instance.in_port`; the agent resolves its address from the receiving
host's `hello.data` (local instances) unless `to_addr` gives it explicitly. A composite
(launcher `composite`, sdrpeer.launch.composite) names its members' ports `Member.port`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Any

from sdrpeer.errors import SpecError, shown
from sdrpeer.launch.composite import parse_composite
from sdrpeer.launch.launchers import known_launchers
from sdrpeer.vocabulary import InstanceRole, LifecycleState

LAUNCHERS = ("python", "script", "exec", "composite")
_DESIRED_JSON = {LifecycleState.ACTIVE: "active", LifecycleState.INACTIVE: "inactive"}
"""A spec's `desired` as spec files and the API spell it."""
DESIRED = tuple(_DESIRED_JSON.values())
ROLES = tuple(InstanceRole)
POLICY_PUSH = ("all", "fifo", "skip", "new")
POLICY_FULL = ("overwrite", "drop", "block")
_NAME = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}$")
_PORT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")
_MEMBER_PORT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,63}\.[A-Za-z_][A-Za-z0-9_]{0,63}$")
"""A composite's port: `Member.port` (sdrpeer.sdk.composite)."""
_PY_TARGET = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")
_ADDR = re.compile(r"^(tcp://[^/\s:]+:\d{1,5}|unix:///\S+)$")
_INSTANCE_KEYS = frozenset(
    {
        "name",
        "component",
        "launcher",
        "target",
        "params",
        "desired",
        "role",
        "connections",
        "watchdog_s",
    }
)
_CONN_KEYS = frozenset({"id", "out", "to", "in", "policy", "to_addr"})


INSTANCE_ACTIONS = ("activate", "deactivate", "reset", "restart", "step")
"""What can be asked of a running instance (`POST /v1/instances/NAME/ACTION`)."""


@dataclass(frozen=True, slots=True)
class ConnectionSpec:
    """A data stream from one of this instance's OutPorts to another instance's InPort."""

    id: str
    """Connection id, unique among the sender's connections."""
    out_port: str
    """The sending OutPort (on the instance that owns this spec)."""
    to_instance: str
    """The receiving instance's name."""
    in_port: str
    """The receiving InPort."""
    policy: tuple[tuple[str, Any], ...] = ()
    """Connector policy (docs/protocol.md), as sorted (key, value) pairs so the spec hashes."""
    to_addr: str | None = None
    """Explicit data address of the receiver (tests, or a remote robot until gossip resolves it)."""
    pending: bool = False
    """The receiver is on another robot and its address is not known yet (it is starting, or
    moving): the connection already made is kept as it is, and re-pointed once the address is
    known; none is made meanwhile. (Dropping it would lose what its sender still holds.)"""

    def policy_map(self) -> dict[str, Any]:
        """The policy as the control channel's map."""
        return dict(self.policy)


@dataclass(frozen=True, slots=True)
class InstanceSpec:
    """One component instance this robot should host."""

    name: str
    """Instance name, unique on the robot (e.g. CameraRTC2)."""
    component: str
    """Logical component name (e.g. CameraRTC)."""
    launcher: str
    """How the host starts: python (module:Class), script (file.py[:Class]), exec (argv), plugin."""
    target: str | tuple[str, ...]
    """What the launcher runs: a string, or an argv tuple for exec."""
    params: tuple[tuple[str, Any], ...] = ()
    """Initial parameters as sorted (name, value) pairs (hashable; see `params_map`)."""
    desired: LifecycleState = LifecycleState.ACTIVE
    """The lifecycle state the instance should be kept in: ACTIVE or INACTIVE."""
    role: InstanceRole = InstanceRole.ACTIVE
    """active, or standby: a standby is started and kept INACTIVE (warm) whatever `desired` is."""
    connections: tuple[ConnectionSpec, ...] = field(default=())
    """Data streams leaving this instance."""
    watchdog_s: float | None = None
    """Seconds the host may go without a heartbeat before it is killed as hung (None: the
    supervisor's default, 0: none)."""

    def params_map(self) -> dict[str, Any]:
        """The parameters as a dict."""
        return dict(self.params)

    def wants_active(self) -> bool:
        """Whether the instance should end up ACTIVE."""
        return self.desired == LifecycleState.ACTIVE and self.role == InstanceRole.ACTIVE

    def same_process(self, other: InstanceSpec) -> bool:
        """Whether a host started for `other` can serve this spec (only lifecycle/links differ)."""
        return (self.component, self.launcher, self.target, self.params) == (
            other.component,
            other.launcher,
            other.target,
            other.params,
        )

    @classmethod
    def from_json(cls, doc: Any, where: str = "instance") -> InstanceSpec:
        """Validate a JSON object into a spec; errors name the field under `where`."""
        if not isinstance(doc, Mapping):
            raise SpecError(where, "expected an object")
        _no_unknown(doc, _INSTANCE_KEYS, where)
        name = _name(doc.get("name"), f"{where}.name")
        launcher = _launcher(doc.get("launcher", "python"), f"{where}.launcher")
        target = _target(launcher, doc.get("target"), f"{where}.target")
        default = name if launcher == "composite" else _default_component(name, target)
        component = _name(doc.get("component", default), f"{where}.component")
        params = doc.get("params", {})
        if not isinstance(params, Mapping) or not all(isinstance(k, str) for k in params):
            raise SpecError(f"{where}.params", "expected an object with string keys")
        conns = doc.get("connections", [])
        if not isinstance(conns, list):
            raise SpecError(f"{where}.connections", "expected a list")
        composite = launcher == "composite"
        connections = tuple(
            _connection(name, c, f"{where}.connections[{i}]", composite=composite)
            for i, c in enumerate(conns)
        )
        ids = [c.id for c in connections]
        for i, cid in enumerate(ids):
            if cid in ids[:i]:
                raise SpecError(f"{where}.connections[{i}].id", f"{cid!r} given twice")
        return cls(
            name=name,
            component=component,
            launcher=launcher,
            target=target,
            params=tuple(sorted(params.items())),
            desired=_desired(doc.get("desired", desired_to_json(LifecycleState.ACTIVE)), where),
            role=InstanceRole(
                _choice(doc.get("role", InstanceRole.ACTIVE), ROLES, f"{where}.role")
            ),
            connections=connections,
            watchdog_s=_watchdog(doc.get("watchdog_s"), f"{where}.watchdog_s"),
        )

    def to_json(self) -> dict[str, Any]:
        """The JSON object `from_json` reads back into an equal spec."""
        return {
            "name": self.name,
            "component": self.component,
            "launcher": self.launcher,
            "target": list(self.target) if isinstance(self.target, tuple) else self.target,
            "params": self.params_map(),
            "desired": desired_to_json(self.desired),
            "role": self.role,
            "connections": [connection_to_json(c) for c in self.connections],
            "watchdog_s": self.watchdog_s,
        }


def desired_to_json(desired: LifecycleState) -> str:
    """A spec's `desired` as spec files and the API spell it (active, inactive)."""
    return _DESIRED_JSON[desired]


def _desired(value: Any, where: str) -> LifecycleState:
    spelled = _choice(value, DESIRED, f"{where}.desired")
    return next(s for s, text in _DESIRED_JSON.items() if text == spelled)


def connection_to_json(c: ConnectionSpec) -> dict[str, Any]:
    """A connection spec as JSON (the keys `from_json` reads)."""
    doc: dict[str, Any] = {
        "id": c.id,
        "out": c.out_port,
        "to": c.to_instance,
        "in": c.in_port,
        "policy": c.policy_map(),
    }
    if c.to_addr is not None:
        doc["to_addr"] = c.to_addr
    return doc


def default_conn_id(sender: str, out_port: str, to_instance: str, in_port: str) -> str:
    """'Cam.image->Viewer.image': the id a connection gets when none is given."""
    return f"{sender}.{out_port}->{to_instance}.{in_port}"


def validate_policy(policy: Any, where: str) -> tuple[tuple[str, Any], ...]:
    """Check a connector policy map (docs/protocol.md) and return it as sorted pairs."""
    if not isinstance(policy, Mapping):
        raise SpecError(where, "expected an object")
    _no_unknown(policy, frozenset({"push", "buffer", "full", "skip", "encrypt"}), where)
    if "encrypt" in policy and not isinstance(policy["encrypt"], bool):
        raise SpecError(f"{where}.encrypt", f"expected true or false, got {policy['encrypt']!r}")
    if "push" in policy:
        _choice(policy["push"], POLICY_PUSH, f"{where}.push")
    if "full" in policy:
        _choice(policy["full"], POLICY_FULL, f"{where}.full")
    for key, low in (("buffer", 1), ("skip", 0)):
        value = policy.get(key, low)
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise SpecError(f"{where}.{key}", f"expected an integer >= {low}, got {shown(value)}")
    return tuple(sorted(policy.items()))


def _connection(sender: str, doc: Any, where: str, *, composite: bool = False) -> ConnectionSpec:
    """A connection leaving `sender`; its `out` may be `Member.port` only when the sender is a
    composite, its `in` may be (the receiver may be one; its host refuses a port it lacks)."""
    if not isinstance(doc, Mapping):
        raise SpecError(where, "expected an object")
    _no_unknown(doc, _CONN_KEYS, where)
    out_port = _port(doc.get("out"), f"{where}.out", member=composite)
    to_instance = _name(doc.get("to"), f"{where}.to")
    in_port = _port(doc.get("in"), f"{where}.in", member=True)
    cid = doc.get("id", default_conn_id(sender, out_port, to_instance, in_port))
    if not isinstance(cid, str) or not 0 < len(cid) <= 255:
        raise SpecError(f"{where}.id", f"expected a non-empty string, got {cid!r}")
    to_addr = doc.get("to_addr")
    if to_addr is not None and (not isinstance(to_addr, str) or not _ADDR.match(to_addr)):
        raise SpecError(
            f"{where}.to_addr", f"expected tcp://HOST:PORT or unix:///path, got {to_addr!r}"
        )
    policy = validate_policy(doc.get("policy", {}), f"{where}.policy")
    return ConnectionSpec(cid, out_port, to_instance, in_port, policy, to_addr)


def _default_component(name: str, target: str | tuple[str, ...]) -> str:
    if isinstance(target, tuple):
        return name
    if ":" in target:
        return target.rsplit(":", 1)[1]
    return PurePath(target).stem or name


def _no_unknown(doc: Mapping[str, Any], known: frozenset[str], where: str) -> None:
    for key in doc:
        if key not in known:
            raise SpecError(f"{where}.{key}", f"unknown field (known: {', '.join(sorted(known))})")


def _name(value: Any, where: str) -> str:
    if not isinstance(value, str) or not _NAME.match(value):
        raise SpecError(where, f"expected a name of [A-Za-z0-9_.-] (1-128), got {shown(value)}")
    return value


def _port(value: Any, where: str, *, member: bool = False) -> str:
    """A port name: an identifier, or with `member` also a composite's `Member.port`."""
    if isinstance(value, str) and (_PORT.match(value) or (member and _MEMBER_PORT.match(value))):
        return value
    form = "an identifier, or Member.port on a composite" if member else "an identifier"
    raise SpecError(where, f"expected a port name ({form}), got {shown(value)}")


def _launcher(value: Any, where: str) -> str:
    if value in LAUNCHERS:
        return str(value)
    known = known_launchers()
    if value not in known:
        raise SpecError(where, f"expected one of {', '.join(known)}, got {shown(value)}")
    return str(value)


def _watchdog(value: Any, where: str) -> float | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise SpecError(where, "expected a number of seconds or null")
    if value != 0 and not 0.5 <= value <= 600:
        raise SpecError(where, f"{value!r} is out of range (0 for none, or 0.5 to 600)")
    return float(value)


def _choice(value: Any, choices: tuple[str, ...], where: str) -> str:
    if value not in choices:
        raise SpecError(where, f"expected one of {', '.join(choices)}, got {shown(value)}")
    return str(value)


def _target(launcher: str, value: Any, where: str) -> str | tuple[str, ...]:
    if launcher == "exec":
        if (
            not isinstance(value, list | tuple)
            or not value
            or not all(isinstance(v, str) and v for v in value)
        ):
            raise SpecError(
                where, f"exec needs an argv list of non-empty strings, got {shown(value)}"
            )
        return tuple(value)
    if not isinstance(value, str) or not value:
        raise SpecError(where, f"expected a string, got {shown(value)}")
    if launcher == "python" and not _PY_TARGET.match(value):
        raise SpecError(where, f"expected package.module:Class, got {shown(value)}")
    if launcher == "composite":
        try:
            parse_composite(value)
        except ValueError as exc:
            raise SpecError(where, str(exc)) from None
    return value
