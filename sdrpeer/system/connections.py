"""The `connections:` section: data streams and service bindings, `from: Comp.port` -> `to:`.

How it works: each end is split at its last dot into a component of the `components:` section and
a port name. When the component's class was imported (python launcher), the `from` port must be
one of its OutPorts and the `to` port one of its InPorts, and when both ports declare a message
type the two must be the same (sdrpeer.sdk.typed; the receiving host refuses a mismatch too,
when the sender connects); otherwise only the form of the name is checked (the host reports its
ports when it starts). A service binding (sdrpeer.sdk.services) is a connection from a consumer's
`ServiceConsumer` port to a provider's `ServiceProvider` port: both ends must be service ports of
one interface id, the consumer at `from` (a binding the wrong way round says so), a consumer is
bound once, and its policy may only set `encrypt`. The policy is checked by the instance spec's
`validate_policy`, so every policy that loads can be sent to an agent. Traffic is `traffic:` when
given, else the sender's profiled rate for that port, else unknown (None). The same stream given
twice is an error. An end naming a member of a composite (`Cam.image`, sdrpeer.system.composites)
is checked against the member's class and becomes its composite's port (`Vision`, `Cam.image`).
An end may be a ROS 2 topic instead (`from: {ros2: /odom}`): the connection then runs to or from
a bridge component made for it (sdrpeer.system.ros2_ends).
`constraints:` holds the connection's own Table II bounds (rssi_above, jitter_below,
distance_below, loss_below, delay_below), which narrow the fleet's when its ends run on two robots.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import yaml

from sdrpeer.errors import SpecError, shown
from sdrpeer.runtime.spec import _port, validate_policy
from sdrpeer.system.components import ComponentEntry
from sdrpeer.system.composites import Member
from sdrpeer.system.model import ConnectionDef, Thresholds
from sdrpeer.system.problems import MISSING, Problems
from sdrpeer.system.ros2_ends import bridge_for, is_ros2_end, read_ros2_end
from sdrpeer.system.sections import LINK_KEYS, read_thresholds
from sdrpeer.system.values import parse_bandwidth

CONNECTION_KEYS = ("from", "to", "policy", "traffic", "constraints")
_KIND = {"from": ("out", "OutPort"), "to": ("in", "InPort")}
_SERVICE = {"from": "requires", "to": "provides"}
"""The service-port kind each end may be instead (a binding: consumer -> provider)."""


def read_connections(
    p: Problems,
    node: yaml.Node | None,
    components: dict[str, ComponentEntry],
    members: Mapping[str, Member] | None = None,
) -> tuple[ConnectionDef, ...]:
    """Every connection (problems recorded in `p`); `components` includes the composites, and
    an end naming a member (`Cam.image`) is its composite's port (`Vision`, `Cam.image`)."""
    members = members or {}
    if node is None:
        return ()
    out: list[ConnectionDef] = []
    seen: dict[str, int] = {}
    bound: dict[tuple[str, str], int] = {}  # consumer port -> line of its binding
    for i, item in enumerate(p.sequence(node, "connections")):
        where = f"connections[{i}]"
        before = len(p.items)  # a missing end is recorded by `mapping`: count it too
        fields = p.mapping(item, where, CONNECTION_KEYS, ("from", "to"))
        if fields is None:
            continue
        policy: Any = ()
        if "policy" in fields:
            policy = _policy(p, fields["policy"], f"{where}.policy")
        ros = [k for k in ("from", "to") if is_ros2_end(p, fields.get(k))]
        if ros:
            sender, receiver = _ros2_connection(
                p, fields, ros, where, components=components, members=members, policy=policy
            )
        else:
            sender = _end(p, fields, "from", where, components, members=members)
            receiver = _end(p, fields, "to", where, components, members=members)
        _same_type(p, (item, where), components, sender, receiver)
        service = _service(p, (item, where), components, sender, receiver)
        if "policy" in fields and service and any(key != "encrypt" for key, _ in policy):
            p.add(fields["policy"], f"{where}.policy", "a service binding sets only encrypt")
        if service and sender in bound:
            p.add(item, where, f"{'.'.join(sender)} is bound already (line {bound[sender]})")
        elif service:
            bound[sender] = item.start_mark.line + 1
        traffic: float | None = p.get(fields, "traffic", where, parse_bandwidth, None)
        bounds = Thresholds()
        if "constraints" in fields:
            bounds = read_thresholds(p, fields["constraints"], f"{where}.constraints", LINK_KEYS)
        if len(p.items) != before or MISSING in (*sender, *receiver):
            continue  # (an end in a composite that is in error was reported there)
        entry = components[sender[0]].definition
        if traffic is None and entry is not None and not service:
            traffic = entry.requires.port_rate(sender[1])
        conn = ConnectionDef(
            *sender, *receiver, policy=policy, traffic_bytes_per_s=traffic, bounds=bounds
        )
        if conn.id in seen:
            p.add(item, where, f"{conn.id} given twice (first at line {seen[conn.id]})")
            continue
        seen[conn.id] = item.start_mark.line + 1
        out.append(conn)
    return tuple(out)


def _end(
    p: Problems,
    fields: dict[str, yaml.Node],
    key: str,
    where: str,
    components: dict[str, ComponentEntry],
    *,
    members: Mapping[str, Member],
) -> tuple[str, str]:
    """(component, port) of one end; MISSING pair when it is wrong (already recorded)."""
    node = fields.get(key)
    field = f"{where}.{key}"
    if node is None:
        return MISSING, MISSING
    value = p.f.value(node)
    comp, dot, port = value.rpartition(".") if isinstance(value, str) else ("", "", "")
    if not dot or not comp or not port:
        p.add(node, field, f"expected Component.port, got {shown(value)}")
        return MISSING, MISSING
    member = members.get(comp)
    if comp not in components and member is None:
        known = ", ".join([*components, *members]) or "none"
        p.add(node, field, f"no component {comp!r} (known: {known})")
        return MISSING, MISSING
    try:
        _port(port, field)
    except SpecError as e:
        p.add(node, field, str(e).split("': ", 1)[-1])
        return MISSING, MISSING
    info = components[comp].info if member is None else member.entry.info
    kind, kind_name = _KIND[key]
    if info is not None and info.port_kind(port) not in (kind, _SERVICE[key]):
        if info.port_kind(port) == _SERVICE["to" if key == "from" else "from"]:
            role = "provides" if key == "from" else "requires"
            p.add(
                node,
                field,
                f"{comp}.{port} {role} a service: a binding goes from: the consumer "
                "(ServiceConsumer) to: the provider (ServiceProvider)",
            )
            return MISSING, MISSING
        cls = info.cls.__name__
        if info.port_kind(port) is None:
            message = f"{cls} has no port {port!r} ({kind_name}s: {info.ports_text(kind)})"
        else:
            message = f"{comp}.{port} is not an {kind_name} of {cls} ({kind_name}s: "
            message += f"{info.ports_text(kind)})"
        p.add(node, field, message)
        return MISSING, MISSING
    if member is not None:
        if member.composite not in components:  # its composite is in error (recorded there)
            return MISSING, MISSING
        return member.composite, f"{comp}.{port}"
    return comp, port


def _ros2_connection(
    p: Problems,
    fields: dict[str, yaml.Node],
    ros: list[str],
    where: str,
    *,
    components: dict[str, ComponentEntry],
    members: Mapping[str, Member],
    policy: tuple[tuple[str, Any], ...],
) -> tuple[tuple[str, str], tuple[str, str]]:
    """(sender, receiver) of a connection with a `ros2:` end (sdrpeer.system.ros2_ends): the
    bridge at that end, made on first use."""
    missing = (MISSING, MISSING)
    if len(ros) == 2:
        p.add(
            fields["from"],
            where,
            "both ends are ROS 2 topics: a connection needs one sdrpeer end (remap in ROS 2)",
        )
        return missing, missing
    key = ros[0]
    other_key = "to" if key == "from" else "from"
    end = read_ros2_end(p, fields[key], f"{where}.{key}")
    other = _end(p, fields, other_key, where, components, members=members)
    if end is None or MISSING in other:
        return missing, missing
    info, peer = components[other[0]].info, components[other[0]].definition
    if end.service and info is not None:
        wanted = "requires" if key == "to" else "provides"
        if info.port_kind(other[1]) != wanted:
            role = "ServiceConsumer" if wanted == "requires" else "ServiceProvider"
            p.add(
                fields[other_key],
                f"{where}.{other_key}",
                f"a ros2_service end binds a {role}(ROS2_SERVICE) port "
                f"(sdrpeer.ros2.services); {'.'.join(other)} is not one",
            )
            return missing, missing
    peer_type = None if info is None else info.port_type(other[1])
    bridge = bridge_for(
        p,
        end,
        key=key,
        field=f"{where}.{key}",
        peer_type=peer_type,
        policy=dict(policy),
        components=components,
        standby=None if peer is None else peer.standby,
    )
    return (bridge, other) if key == "from" else (other, bridge)


def _same_type(
    p: Problems,
    at: tuple[yaml.Node, str],
    components: dict[str, ComponentEntry],
    sender: tuple[str, str],
    receiver: tuple[str, str],
) -> None:
    """Two typed ends must carry the same message type (an untyped end takes any)."""
    if MISSING in (*sender, *receiver):
        return
    out_info, in_info = components[sender[0]].info, components[receiver[0]].info
    sends = None if out_info is None else out_info.port_type(sender[1])
    takes = None if in_info is None else in_info.port_type(receiver[1])
    if sends is not None and takes is not None and sends != takes:
        p.add(*at, f"{'.'.join(sender)} sends {sends} but {'.'.join(receiver)} takes {takes}")


def _service(
    p: Problems,
    at: tuple[yaml.Node, str],
    components: dict[str, ComponentEntry],
    sender: tuple[str, str],
    receiver: tuple[str, str],
) -> bool:
    """True for a service binding (either end a service port, when the classes are known);
    a data port at the other end, or another interface, is recorded."""
    if MISSING in (*sender, *receiver):
        return False
    out_info, in_info = components[sender[0]].info, components[receiver[0]].info
    requires = None if out_info is None else out_info.interface(sender[1])
    provides = None if in_info is None else in_info.interface(receiver[1])
    if requires is None and provides is None:
        return False
    if requires is not None and provides is not None:
        if requires != provides:
            p.add(
                *at,
                f"{'.'.join(sender)} requires {requires} but {'.'.join(receiver)} provides "
                f"{provides}",
            )
        return True
    if out_info is not None and in_info is not None:  # one service port, one data port
        service, data = (sender, receiver) if requires is not None else (receiver, sender)
        p.add(
            *at,
            f"{'.'.join(service)} is a service port but {'.'.join(data)} is a data port",
        )
    return True


def _policy(p: Problems, node: yaml.Node, where: str) -> tuple[tuple[str, Any], ...]:
    try:
        return validate_policy(p.f.value(node), where)
    except SpecError as e:
        inner = node
        if isinstance(node, yaml.MappingNode):
            key = e.field.rsplit(".", 1)[-1]
            inner = next((v for k, v in node.value if p.f.value(k) == key), node)
        p.add(inner, e.field, str(e).split("': ", 1)[-1])
        return ()
