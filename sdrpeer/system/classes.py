"""What a component class declares (ports, params), for checking a system file against it.

How it works: for the `python` launcher (`package.module:Class`) the class is imported the way a
host imports it (sdrpeer.host.loader) and its declared in- and out-ports (with the message type
of each typed port) and params are read from the class, without creating an instance. Other
launchers (`script`, `exec`, plugins) run code we do not import at load time: `inspect_target`
returns None for them and their ports and params are taken on trust (the host reports them when
it starts). A class that cannot be imported is a `ValueError` naming the target and the reason.
`check_params` converts each param with the class's own `Param.convert` (types, choices, min and
max), so a bad value fails at load time rather than when the host starts.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sdrpeer.errors import SdrpeerError
from sdrpeer.host.loader import load_component_class
from sdrpeer.sdk import Component


@dataclass(frozen=True, slots=True)
class ClassInfo:
    """The declarations of one component class."""

    cls: type[Component]
    in_ports: tuple[str, ...]
    out_ports: tuple[str, ...]
    types: tuple[tuple[str, str], ...] = ()
    """(port, message type id) of every typed port (sdrpeer.sdk.typed)."""

    def port_type(self, port: str) -> str | None:
        """The port's message type id, None when it takes or sends any value."""
        return dict(self.types).get(port)

    def port_kind(self, port: str) -> str | None:
        """'in', 'out', or None when the class declares no such port."""
        if port in self.in_ports:
            return "in"
        if port in self.out_ports:
            return "out"
        return None

    def ports_text(self, kind: str) -> str:
        """The class's ports of one kind, for messages."""
        names = self.in_ports if kind == "in" else self.out_ports
        return ", ".join(names) or "none"


def inspect_target(launcher: str, target: str | tuple[str, ...]) -> ClassInfo | None:
    """The class a `python` launcher target names (None for other launchers)."""
    if launcher != "python" or not isinstance(target, str):
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
    return ClassInfo(cls, tuple(names["in"]), tuple(names["out"]), types)


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
