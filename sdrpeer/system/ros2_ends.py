"""A connection end on a ROS 2 topic: `from: {ros2: /odom}` or `to: {ros2: /pose}`, read into a
bridge component (sdrpeer.ros2.bridge) and an ordinary connection to it.

How it works: a ROS 2 end is a mapping with `ros2:` (the topic, absolute), optionally `type:` and
`qos:`. Its bridge is one component per topic and direction, named `ros2-<topic>-sub` (ROS 2 ->
sdrpeer: `FromRos<Type>`, port `out`) or `ros2-<topic>-pub` (sdrpeer -> ROS 2: `ToRos<Type>`,
port `input`), with the `ros2` launcher; several connections of one topic and direction share
it. The message type is the sdrpeer end's typed port when its class is known (one of the
standard robot types, sdrpeer.ros2.types), else `type:` (a standard type's name, `Odometry`, or
a ROS 2 type, `nav_msgs/msg/Odometry`; a ROS 2 type without a mapping travels as the untyped map
of its fields). QoS: `depth` is the connection policy's `buffer` (default 10), `reliability` is
`best_effort` when the policy pushes only the newest (`push: new`) else `reliable`, `durability`
is `volatile`; `qos:` (reliability, depth, durability) overrides each. The bridge is placed,
moved and recovered like any component, with the standbys of the component at its sdrpeer end
(of the more guarded one, when several share it);
its requirements are a ROS 2 process's (`BRIDGE_NEEDS`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Final

import yaml

from sdrpeer.errors import shown
from sdrpeer.ros2.bridge import DURABILITY, RELIABILITY, bridge_class_name
from sdrpeer.ros2.types import mapping_for
from sdrpeer.system.classes import class_info
from sdrpeer.system.components import ComponentEntry
from sdrpeer.system.model import ComponentDef, Requirements, StandbySpec
from sdrpeer.system.problems import MISSING, Problems

__all__ = ["BRIDGE_NEEDS", "ROS2_END_KEYS", "Ros2End", "bridge_for", "read_ros2_end"]

ROS2_END_KEYS: Final = ("ros2", "type", "qos")
SERVICE_END_KEYS: Final = ("ros2_service", "type")
QOS_KEYS: Final = ("reliability", "depth", "durability")
BRIDGE_NEEDS: Final = Requirements(cpu_pct=5.0, mem_bytes=90_000_000)
"""What one bridge host takes: an rclpy process with Fast DDS (~80 MB RSS measured on this
project's machines), a few percent of a core at 50 Hz."""
_PORT: Final = {"from": "out", "to": "input"}


@dataclass(frozen=True, slots=True)
class Ros2End:
    """One `ros2:` end as written."""

    topic: str
    """The topic, or the service of a `ros2_service:` end."""
    type: str | None
    qos: tuple[tuple[str, Any], ...]
    node: yaml.Node
    service: bool = False


def is_ros2_end(p: Problems, node: yaml.Node | None) -> bool:
    """Whether an end is a `{ros2: ...}` mapping (not yet checked)."""
    if not isinstance(node, yaml.MappingNode):
        return False
    return any(p.f.value(k) in ("ros2", "ros2_service") for k, _ in node.value)


def read_ros2_end(p: Problems, node: yaml.Node, field: str) -> Ros2End | None:
    """The end's fields (problems recorded; None when it is wrong)."""
    if any(p.f.value(k) == "ros2_service" for k, _ in node.value):
        return _read_service_end(p, node, field)
    before = len(p.items)
    fields = p.mapping(node, field, ROS2_END_KEYS, ("ros2",))
    if fields is None:
        return None
    topic = p.f.value(fields["ros2"]) if "ros2" in fields else None
    if not isinstance(topic, str) or not _valid_topic(topic):
        p.add(
            fields.get("ros2", node),
            f"{field}.ros2",
            f"expected an absolute ROS 2 topic name like /odom, got {shown(topic)}",
        )
    kind = p.f.value(fields["type"]) if "type" in fields else None
    if kind is not None and (not isinstance(kind, str) or not _valid_type(kind)):
        p.add(
            fields["type"],
            f"{field}.type",
            f"expected a standard type (Pose, Odometry, ...) or pkg/msg/Name, got {shown(kind)}",
        )
    qos: list[tuple[str, Any]] = []
    if "qos" in fields:
        q = p.mapping(fields["qos"], f"{field}.qos", QOS_KEYS) or {}
        for key, value_node in q.items():
            value = p.f.value(value_node)
            ok = (
                value in RELIABILITY
                if key == "reliability"
                else value in DURABILITY
                if key == "durability"
                else isinstance(value, int) and not isinstance(value, bool) and value >= 1
            )
            if not ok:
                choices = {"reliability": RELIABILITY, "durability": DURABILITY}.get(key)
                expected = ", ".join(choices) if choices else "an integer >= 1"
                p.add(value_node, f"{field}.qos.{key}", f"expected {expected}, got {shown(value)}")
            qos.append((key, value))
    if len(p.items) != before:
        return None
    assert isinstance(topic, str)
    return Ros2End(topic, kind, tuple(sorted(qos)), node)


def _read_service_end(p: Problems, node: yaml.Node, field: str) -> Ros2End | None:
    """A `{ros2_service: /name, type: pkg/srv/Name}` end."""
    before = len(p.items)
    fields = p.mapping(node, field, SERVICE_END_KEYS, SERVICE_END_KEYS)
    if fields is None:
        return None
    name = p.f.value(fields["ros2_service"]) if "ros2_service" in fields else None
    if "ros2_service" in fields and (not isinstance(name, str) or not _valid_topic(name)):
        p.add(
            fields["ros2_service"],
            f"{field}.ros2_service",
            f"expected an absolute ROS 2 service name like /reset, got {shown(name)}",
        )
    kind = p.f.value(fields["type"]) if "type" in fields else None
    if "type" in fields and (
        not isinstance(kind, str) or kind.count("/") != 2 or "/srv/" not in kind
    ):
        p.add(fields["type"], f"{field}.type", f"expected pkg/srv/Name, got {shown(kind)}")
    if len(p.items) != before:
        return None
    assert isinstance(name, str)
    assert isinstance(kind, str)
    return Ros2End(name, kind, (), node, service=True)


def _valid_topic(topic: str) -> bool:
    parts = topic.split("/")
    return (
        topic.startswith("/")
        and len(topic) > 1
        and all(part and (part[0].isalpha() or part[0] == "_") for part in parts[1:])
        and all(c.isalnum() or c in "_/" for c in topic)
    )


def _valid_type(kind: str) -> bool:
    parts = kind.split("/")
    return all(part.isidentifier() for part in parts) and len(parts) in (1, 2, 3)


def bridge_name(end: Ros2End, key: str) -> str:
    """`ros2-odom-sub` for `from: {ros2: /odom}`, `ros2-robot1_pose-pub` for a `to:` end;
    `-server` / `-client` for a service end."""
    body = end.topic.strip("/").replace("/", "_")
    roles = ("server", "client") if end.service else ("sub", "pub")
    return f"ros2-{body}-{roles[0] if key == 'from' else roles[1]}"


def _definition(
    name: str, target: str, params: dict[str, Any], standby: StandbySpec | None
) -> ComponentDef:
    """A bridge component: the ros2 launcher, a ROS 2 process's needs, its peer's standbys."""
    return ComponentDef(
        name,
        "ros2",
        target,
        tuple(sorted(params.items())),
        requires=BRIDGE_NEEDS,
        standby=standby or StandbySpec(),
    )


def _same_name(p: Problems, end: Ros2End, field: str, have: ComponentEntry, name: str) -> bool:
    """False (recorded) when the bridge already called `name` serves another topic or service
    (`/a/b` and `/a_b` make one name)."""
    assert have.definition is not None
    params = have.definition.params_map()
    other = params.get("service" if end.service else "topic")
    if other == end.topic:
        return True
    p.add(
        end.node,
        field,
        f"{end.topic} and {other} (line {have.node.start_mark.line + 1}) make one bridge name, "
        f"{name}; a system bridges only one of them (rename one in ROS 2)",
    )
    return False


def bridge_for(
    p: Problems,
    end: Ros2End,
    *,
    key: str,
    field: str,
    peer_type: str | None,
    policy: dict[str, Any],
    components: dict[str, ComponentEntry],
    standby: StandbySpec | None = None,
) -> tuple[str, str]:
    """The bridge of `end` (made and added to `components` the first time; `key` is the end's
    side, `from` or `to`) and its port; MISSING when the type cannot be settled (recorded).
    A service end's bridge is `ToRosService` (`to:`, the sdrpeer consumer calls ROS 2) or
    `FromRosService` (`from:`, ROS 2 clients call the sdrpeer provider), port `ros`.
    `peer_type` is the type id of the sdrpeer end's port (None: untyped or unknown); the bridge
    keeps the standbys of the component at the sdrpeer end (`standby`), so that it fails over
    as fast as that component does."""
    if end.service:
        return _service_bridge(p, end, key, field=field, components=components, standby=standby)
    settled = _settle_type(p, end, field, peer_type)
    if settled is None:
        return MISSING, MISSING
    kind, ros_type = settled
    qos = {
        "depth": int(policy.get("buffer", 10)),
        "reliability": "best_effort" if policy.get("push") == "new" else "reliable",
        "durability": "volatile",
        **dict(end.qos),
    }
    params: dict[str, Any] = {"topic": end.topic, **qos}
    if ros_type:
        params["ros_type"] = ros_type
    from sdrpeer.ros2 import bridge  # noqa: PLC0415 - its classes by name

    cls_name = bridge_class_name(key, kind)
    name = bridge_name(end, key)
    definition = _definition(name, f"sdrpeer.ros2.bridge:{cls_name}", params, standby)
    have = components.get(name)
    if have is not None and have.definition is not None:
        if not _same_name(p, end, field, have, name):
            return MISSING, MISSING
        if replace(have.definition, standby=definition.standby) != definition:
            p.add(
                end.node,
                field,
                f"{end.topic} is bridged {'from' if key == 'from' else 'to'} ROS 2 at line "
                f"{have.node.start_mark.line + 1} with another type or QoS; give them the same",
            )
            return MISSING, MISSING
        wider = _wider(have.definition.standby, definition.standby)
        have.definition = replace(have.definition, standby=wider)
        return name, _PORT[key]
    components[name] = ComponentEntry(
        end.node, field, class_info(getattr(bridge, cls_name)), definition
    )
    return name, _PORT[key]


def _service_bridge(
    p: Problems,
    end: Ros2End,
    key: str,
    *,
    field: str,
    components: dict[str, ComponentEntry],
    standby: StandbySpec | None,
) -> tuple[str, str]:
    """The bridge of a `ros2_service:` end (one per service and side, shared)."""
    from sdrpeer.ros2 import services  # noqa: PLC0415 - its classes by name

    cls_name = "FromRosService" if key == "from" else "ToRosService"
    name = bridge_name(end, key)
    params = {"service": end.topic, "srv_type": end.type}
    definition = _definition(name, f"sdrpeer.ros2.services:{cls_name}", params, standby)
    have = components.get(name)
    if have is not None and have.definition is not None:
        if not _same_name(p, end, field, have, name):
            return MISSING, MISSING
        if key == "from":
            p.add(end.node, "connections", f"{end.topic} is served by one component only")
            return MISSING, MISSING
        return name, "ros"
    info = class_info(getattr(services, cls_name))
    components[name] = ComponentEntry(end.node, name, info, definition)
    return name, "ros"


def _wider(a: StandbySpec, b: StandbySpec) -> StandbySpec:
    """The standbys of a bridge shared by two peers: as many as the more guarded one keeps."""
    return a if (a.other_robots, a.same_robot) >= (b.other_robots, b.same_robot) else b


def _settle_type(
    p: Problems, end: Ros2End, field: str, peer_type: str | None
) -> tuple[str | None, str | None] | None:
    """(standard type's short name or None for untyped, ROS 2 type to give as `ros_type`); None
    when it cannot be settled (recorded)."""
    peer_kind = None
    if peer_type is not None:
        short = peer_type.partition("#")[0].removeprefix("sdrpeer/")
        m = mapping_for(short) if peer_type.startswith("sdrpeer/") else None
        if m is None:
            p.add(
                end.node,
                field,
                f"the port carries {peer_type}, which has no ROS 2 mapping (mapped: Pose, "
                "Velocity, Odometry, RangeScan, Image, BatteryState); bridge an untyped port",
            )
            return None
        peer_kind = m.cls.__name__
    if end.type is None:
        if peer_kind is None:
            p.add(
                end.node,
                f"{field}.type",
                "missing: the sdrpeer end's type is not known here; give type: (Odometry, "
                "nav_msgs/msg/Odometry, ...)",
            )
            return None
        return peer_kind, None
    m = mapping_for(end.type)
    if m is None:
        if peer_kind is not None or "/" not in end.type:
            p.add(
                end.node,
                f"{field}.type",
                f"{end.type} is not a standard type"
                + (f" (the port carries {peer_kind})" if peer_kind else ""),
            )
            return None
        return None, end.type  # any ROS 2 type, carried as a map
    if peer_kind is not None and m.cls.__name__ != peer_kind:
        p.add(
            end.node,
            f"{field}.type",
            f"{end.type} is {m.ros_type} but the port carries {peer_kind}",
        )
        return None
    return m.cls.__name__, None
