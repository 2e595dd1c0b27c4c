"""The ports of the instances this agent hosts: names, directions, message types, connections.

How it works: a port is named `Instance.port` (`parse_ref`; the instance name may itself hold
dots, the port is what follows the last one, except that `Catalog.split` first looks for an
instance it knows: a composite member's port holds a dot itself, `Perception.Cam.image`).
What a port is comes from the instance's class when its launcher is `python` (imported once per
target, the way `sdrpeer system check` does: sdrpeer.system.classes; that gives the message type
of typed ports), else from the ports its running host declared in its hello (direction only:
such a port is taken as untyped). A class is
imported in a worker thread (`warm`, before a request uses the catalog), so a slow import does not
hold up the agent's event loop; the launch policy already let the target run here. `Catalog`
answers for the instances in the agent's desired set; an instance it does not host is a
`PortToolError` (404) that names the robot whose gossip record lists it, when one does.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any

from sdrpeer.errors import PortToolError
from sdrpeer.runtime.manager import InstanceManager
from sdrpeer.sdk.typed import MessageType, port_message
from sdrpeer.system.classes import inspect_target

_Declared = dict[str, tuple[str, MessageType | None, str | None]]
_CLASS_PORTS: dict[tuple[str, str], _Declared | None] = {}
"""(launcher, target) -> port -> (direction, message type, interface id): classes already
inspected. A service port's direction is `provides` or `requires` (sdrpeer.sdk.services)."""


@dataclass(frozen=True, slots=True)
class PortFacts:
    """One port of one instance."""

    instance: str
    port: str
    direction: str
    """"in" or "out"."""
    message: MessageType | None = None
    """Its message type (sdrpeer.sdk.typed), None: it takes or sends any value."""
    interface: str | None = None
    """A service port's interface id (sdrpeer.sdk.services), None for a data port."""

    @property
    def ref(self) -> str:
        """'Instance.port'."""
        return f"{self.instance}.{self.port}"

    @property
    def type_id(self) -> str | None:
        """The message type's id (a service port: its interface's), None when untyped."""
        return self.interface if self.message is None else self.message.type_id


def parse_ref(text: str, where: str = "port") -> tuple[str, str]:
    """'Cam.image' -> ('Cam', 'image'); PortToolError (400) naming `where` otherwise."""
    instance, dot, port = str(text).rpartition(".")
    if not dot or not instance or not port.isidentifier():
        raise PortToolError(f"{where}: expected Instance.port (e.g. Cam1.image), got {text!r}")
    return instance, port


def _class_ports(launcher: str, target: Any) -> _Declared | None:
    key = (launcher, str(target))
    if key not in _CLASS_PORTS:
        try:
            info = inspect_target(launcher, target)
        except ValueError:
            info = None
        ports: _Declared | None = None
        if info is not None:
            declared = info.cls._sdk_ports  # the class's declarations, as system check reads
            ports = {
                name: (d.kind, port_message(getattr(d, "type", None)), None)
                for name, d in declared.items()
            }
            for name, service in info.cls.service_ports().items():
                ports[name] = (service.role, None, service.interface)
        _CLASS_PORTS[key] = ports
    return _CLASS_PORTS[key]


class Catalog:
    """What the port tools know of the ports this agent hosts."""

    def __init__(
        self,
        manager: InstanceManager,
        robot: str,
        elsewhere: Callable[[str], tuple[str, str | None] | None] = lambda name: None,
    ) -> None:
        self.manager = manager
        self.robot = robot
        """This robot's name."""
        self.elsewhere = elsewhere
        """Instance -> (robot, API URL) of the robot whose record lists it, None if none does."""

    async def warm(self) -> None:
        """Import, in a worker thread, the classes of hosted instances not inspected yet."""
        for spec in self.manager.desired().values():
            if (spec.launcher, str(spec.target)) not in _CLASS_PORTS:
                await asyncio.to_thread(_class_ports, spec.launcher, spec.target)

    def ports_of(self, instance: str) -> dict[str, PortFacts]:
        """Every port of a hosted instance (PortToolError 404 when it is not hosted here)."""
        spec = self.manager.desired().get(instance)
        if spec is None:
            raise self._not_here(instance)
        declared = _class_ports(spec.launcher, spec.target)
        if declared is not None:
            return {
                name: PortFacts(instance, name, kind, msg, interface)
                for name, (kind, msg, interface) in sorted(declared.items())
            }
        said = self.manager.hello_ports(instance) or {}
        return {
            name: PortFacts(instance, name, kind)
            for kind in ("in", "out")
            for name in sorted(said.get(kind, []))
        }

    def split(self, ref: str, where: str = "port") -> tuple[str, str]:
        """(instance, port) of `Instance.port`, split after the longest instance name this agent
        hosts or the cluster's records list (a composite's member ports hold a dot:
        `Perception.Cam.image`), else at the last dot; PortToolError when it has no such form."""
        instance, port = parse_ref(ref, where)
        text = str(ref)
        desired = self.manager.desired()
        cut = len(instance)
        while cut > 0:
            head = text[:cut]
            if head in desired or self.elsewhere(head) is not None:
                return head, text[cut + 1 :]
            cut = text.rfind(".", 0, cut)
        return instance, port

    def port(self, ref: str, direction: str | None = None, where: str = "port") -> PortFacts:
        """The port `Instance.port` names; PortToolError when unknown or of the other direction."""
        instance, name = self.split(ref, where)
        ports = self.ports_of(instance)
        facts = ports.get(name)
        if facts is None:
            known = ", ".join(ports) or "none known yet: is it running?"
            raise PortToolError(f"{where}: {instance} has no port {name!r} (ports: {known})", 404)
        if direction is not None and facts.direction != direction:
            want = "an out-port" if direction == "out" else "an in-port"
            what = (
                f"a service port ({facts.direction} {facts.interface})"
                if facts.interface is not None
                else f"an {facts.direction}-port"
            )
            raise PortToolError(f"{where}: {ref} is {what}, not {want}", 409)
        return facts

    def owner(self, refs: list[str]) -> tuple[str, str | None] | None:
        """None when every port's instance is hosted here; (robot, API URL) when all are on one
        other robot; PortToolError when one is unknown or they are on several robots."""
        owners: dict[str, str | None] = {}
        desired = self.manager.desired()
        for i, ref in enumerate(refs):
            instance, _ = self.split(ref, f"ports[{i}]")
            if instance in desired:
                owners[self.robot] = None
                continue
            found = self.elsewhere(instance)
            if found is None:
                raise self._not_here(instance)
            owners[found[0]] = found[1]
        if len(owners) > 1:
            robots = " and ".join(sorted(owners))
            raise PortToolError(f"the ports are on {robots}: ask each robot for its own", 409)
        [(robot, api)] = owners.items()
        return None if robot == self.robot else (robot, api)

    def _not_here(self, instance: str) -> PortToolError:
        found = self.elsewhere(instance)
        if found is None:
            return PortToolError(f"no instance {instance!r} on {self.robot} or in the cluster", 404)
        robot, api = found
        where = f" (API {api})" if api else ""
        return PortToolError(
            f"{instance} runs on {robot}, not {self.robot}: ask {robot}'s agent{where}", 404
        )

    def listing(self) -> list[dict[str, Any]]:
        """Every port of every hosted instance: instance, port, direction, type, connections
        (`id`, the other end, run-time or not), the host's counters for it and their rates; then
        a ROS 2 host's topics and services (`ros2: true`, the port a ROS 2 name, the direction
        publishes, subscribes or serves, the type a ROS 2 type)."""
        manager = self.manager
        counters = manager.port_counters()
        rates = manager.port_rates()
        endpoints = manager.endpoints()
        adhoc = {conn.id for _, conn in manager.adhoc_connections()}
        desired = manager.desired()
        rows: list[dict[str, Any]] = []
        for name in sorted(desired):
            made = manager.made_connections(name)
            for facts in self.ports_of(name).values():
                rows.append(
                    {
                        "instance": name,
                        "port": facts.port,
                        "direction": facts.direction,
                        "type": facts.type_id,
                        "connections": list(self._connections(facts, desired, made, adhoc)),
                        "counters": counters.get(name, {}).get(facts.port, {}),
                        "rates": rates.get(name, {}).get(facts.port, {}),
                        "robot": self.robot,
                    }
                )
            for topic, (direction, ros_type) in sorted(endpoints.get(name, {}).items()):
                rows.append(
                    {
                        "instance": name,
                        "port": topic,
                        "direction": direction,
                        "type": ros_type or None,
                        "connections": [],
                        "counters": counters.get(name, {}).get(topic, {}),
                        "rates": rates.get(name, {}).get(topic, {}),
                        "robot": self.robot,
                        "ros2": True,
                    }
                )
        return rows

    def _connections(
        self,
        facts: PortFacts,
        desired: dict[str, Any],
        made: dict[str, Any],
        adhoc: set[str],
    ) -> Iterable[dict[str, Any]]:
        if facts.direction in ("out", "requires"):  # a sender, or a service's caller
            for cid, (conn, addr) in sorted(made.items()):
                if conn.out_port == facts.port:
                    to = f"{conn.to_instance}.{conn.in_port}"
                    yield {"id": cid, "to": to, "addr": addr, "adhoc": cid in adhoc}
            return
        for sender in sorted(desired):
            for cid, (conn, _) in sorted(self.manager.made_connections(sender).items()):
                if conn.to_instance == facts.instance and conn.in_port == facts.port:
                    frm = f"{sender}.{conn.out_port}"
                    yield {"id": cid, "from": frm, "adhoc": cid in adhoc}
