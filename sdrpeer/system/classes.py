"""What a component class declares (ports, params), for checking a system file against it.

How it works: for the `python` launcher (`package.module:Class`) the class is imported the way a
host imports it (sdrpeer.host.loader) and its declared in- and out-ports (with the message type
of each typed port), service ports (with their interface ids) and params are read from the
class, without creating an instance; a `composite` target's class is built from its members'
the way its host builds it (`Member.port` ports). Other launchers (`script`, `exec`, plugins)
run code we do not import at load time: `inspect_target` returns None for them and their ports
and params are taken on trust (the host reports them when it starts). The one exception is the
`ros2` launcher's bridges (`sdrpeer.ros2.bridge:FromRos<Type>`, `ToRos<Type>`): sdrpeer's own
classes, importable without ROS 2, read like a `python` target's (their typed ports are what
`port record --format ros2` needs). A class that cannot be
imported is a `ValueError` naming the target and the reason. `check_params` converts each param
with the class's own `Param.convert` (types, choices, min and max), so a bad value fails at load
time rather than when the host starts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sdrpeer.errors import SdrpeerError
from sdrpeer.host.loader import load_component_class, load_composite_class
from sdrpeer.sdk import Component
from sdrpeer.system.model import SystemDef

ROS2_BRIDGES = "sdrpeer.ros2.bridge:"
"""The `ros2` launcher's targets read like `python` ones: sdrpeer's bridges (no ROS 2 imported)."""


@dataclass(frozen=True, slots=True)
class ClassInfo:
    """The declarations of one component class."""

    cls: type[Component]
    in_ports: tuple[str, ...]
    out_ports: tuple[str, ...]
    types: tuple[tuple[str, str], ...] = ()
    """(port, message type id) of every typed port (sdrpeer.sdk.typed)."""
    provides: tuple[tuple[str, str], ...] = ()
    """(port, interface id) of every provided service port (sdrpeer.sdk.services)."""
    requires: tuple[tuple[str, str], ...] = ()
    """(port, interface id) of every required service port."""

    def interface(self, port: str) -> str | None:
        """The interface id of a service port, None for any other name."""
        return dict(self.provides).get(port) or dict(self.requires).get(port)

    def port_type(self, port: str) -> str | None:
        """The port's message type id, None when it takes or sends any value."""
        return dict(self.types).get(port)

    def port_kind(self, port: str) -> str | None:
        """'in', 'out', 'provides', 'requires', or None when the class declares no such port."""
        if port in self.in_ports:
            return "in"
        if port in self.out_ports:
            return "out"
        if port in dict(self.provides):
            return "provides"
        if port in dict(self.requires):
            return "requires"
        return None

    def ports_text(self, kind: str) -> str:
        """The class's ports of one kind, for messages."""
        by_kind = {
            "in": self.in_ports,
            "out": self.out_ports,
            "provides": tuple(n for n, _ in self.provides),
            "requires": tuple(n for n, _ in self.requires),
        }
        return ", ".join(by_kind[kind]) or "none"


def inspect_target(launcher: str, target: str | tuple[str, ...]) -> ClassInfo | None:
    """The class a `python` launcher target names, or the class a `composite` target builds
    (None for other launchers)."""
    if launcher == "composite" and isinstance(target, str):
        try:
            return class_info(load_composite_class("Composite", target))
        except SdrpeerError as e:
            raise ValueError(f"cannot build the composite: {e}") from None
    if not isinstance(target, str) or not (
        launcher == "python" or (launcher == "ros2" and target.startswith(ROS2_BRIDGES))
    ):
        return None
    try:
        cls = load_component_class(target, Component)
    except SdrpeerError as e:
        raise ValueError(f"cannot import the component class: {e}") from None
    return class_info(cls)


def class_info(cls: type[Component]) -> ClassInfo:
    """The declarations of a class already at hand (a member's, or a composite's)."""
    names = cls.port_names()
    declared = cls._sdk_ports.items()
    types = tuple((n, t) for n, d in declared if (t := d.type_id) is not None)
    services = cls.service_ports()
    provides = tuple((n, i.interface) for n, i in services.items() if i.role == "provides")
    requires = tuple((n, i.interface) for n, i in services.items() if i.role == "requires")
    return ClassInfo(cls, tuple(names["in"]), tuple(names["out"]), types, provides, requires)


def check_params(info: ClassInfo, params: dict[str, Any]) -> list[tuple[str, str]]:
    """(param, message) for every param the class does not declare or would refuse."""
    declared = info.cls.params()
    bad: list[tuple[str, str]] = []
    for name, value in params.items():
        if name not in declared:
            known = ", ".join(declared) or "none"
            bad.append((name, f"{info.cls.__name__} declares no param {name!r} (known: {known})"))
            continue
        try:
            getattr(info.cls, name).convert(value)
        except SdrpeerError as e:
            bad.append((name, str(e)))
    return bad


def disagreements(system: SystemDef) -> list[str]:
    """What a system document's connections get wrong about the classes this process can import:
    a typed sender and a typed receiver of different message types, a service binding between
    two interfaces, a service port bound to a data port. A class that cannot be imported here
    is not judged (the robot that runs it may have it). The check a document posted to the API
    gets, which no system file loader has seen."""
    infos: dict[str, ClassInfo | None] = {}
    for comp in system.components:
        try:
            infos[comp.name] = inspect_target(comp.launcher, comp.target)
        except Exception:  # another robot's code: whatever its import does, it is not judged
            infos[comp.name] = None
    found: list[str] = []
    for conn in system.connections:
        a, a_port, b, b_port = conn.from_component, conn.from_port, conn.to_component, conn.to_port
        out_info, in_info = infos.get(a), infos.get(b)
        if out_info is None or in_info is None:
            continue
        sender, receiver = f"{a}.{a_port}", f"{b}.{b_port}"
        requires, provides = out_info.interface(a_port), in_info.interface(b_port)
        if requires is not None and provides is not None and requires != provides:
            found.append(f"{sender} requires {requires} but {receiver} provides {provides}")
        elif (requires is None) != (provides is None):
            service, data = (sender, receiver) if requires is not None else (receiver, sender)
            found.append(f"{service} is a service port but {data} is a data port")
        elif requires is None:
            sends, takes = out_info.port_type(a_port), in_info.port_type(b_port)
            if sends is not None and takes is not None and sends != takes:
                found.append(f"{sender} sends {sends} but {receiver} takes {takes}")
    return found
