"""`sdrpeer describe COMPONENT|ROBOT` (kubectl describe): where, why, what happened, what is wrong.

How it works (pure: the route hands in what the agent knows, nothing here does I/O):
- a component: each of its instances with its robot, role, state and the allocator's explanation
  from the plan (`Plan.why`: the robots tried and the constraint that ruled each out, how its
  robot was chosen, the constraints it passed, the objective's scores, the reason and plan that
  decided it); its standby situation (how many the system asks for, how many the plan has, and
  for each one left out why every robot refused it); the connections it has with their traffic
  and lost frames; the links between its active's robot and those of its peers now, against the
  Table II bounds; recent events that name it or one of its instances;
- a robot: its member state, its metrics against the Table I thresholds (and its typical link
  against the Table II ones), what the plan has it host and what it runs, recent events that
  name it;
- warnings, in both: a standby missing or not running, an instance whose robot is down, a
  constraint its robot fails now (battery, RSSI, a link between connected components), a
  connection dropping frames (`lost_per_s`) or a `port.overflow` event, a connection its
  receiver refuses (the latest `conn.refused` event of each connection not followed by its
  `conn.accepted`: why it sends nothing).
Events come from the agent's own log and from the robots concerned (the route gathers them);
`describe` picks those that name the subject as a whole word, newest last.
"""

from __future__ import annotations

import json
from collections.abc import Iterable, Mapping, Sequence
from typing import Any

from sdrpeer.eventlog import EventKind, naming
from sdrpeer.plan import Plan
from sdrpeer.record.robot import state_to_wire
from sdrpeer.system.model import SystemDef, Thresholds
from sdrpeer.vocabulary import InstanceRole, LifecycleState, MemberState

MAX_EVENTS = 25
"""Events shown per subject (the newest)."""

_ACTIVE = state_to_wire(LifecycleState.ACTIVE)


def subject_kind(name: str, plan: Plan | None, members: Sequence[Mapping[str, Any]]) -> str | None:
    """ "component" (a component or one of its instances), "robot", or None when unknown."""
    if plan is not None and plan.system is not None:
        if any(c.name == name for c in plan.system.components):
            return "component"
        if any(p.instance == name for p in plan.placements) or plan.why_of(name) is not None:
            return "component"
    if any(m.get("name") == name for m in members):
        return "robot"
    if plan is not None and any(p.robot == name for p in plan.placements):
        return "robot"
    return None


def component_of(name: str, plan: Plan) -> str:
    """The component called `name`, or the component of the instance called `name`."""
    for p in plan.placements:
        if p.instance == name:
            return p.component
    why = plan.why_of(name)
    return why.component if why is not None else name


def subject_names(name: str, kind: str, plan: Plan | None) -> list[str]:
    """The names events about the subject carry: a robot's own; a component's and those of
    all its instances (placed or left out)."""
    if kind != "component" or plan is None:
        return [name]
    comp = component_of(name, plan)
    out = [comp, *(p.instance for p in plan.placements if p.component == comp)]
    out += [w.instance for w in plan.why if w.component == comp]
    return list(dict.fromkeys(out))


def concerned_robots(name: str, kind: str, plan: Plan | None) -> set[str]:
    """The robots whose event logs may hold events about the subject: a robot itself, a
    component's robots; and the allocator."""
    out = {name} if kind == "robot" else set()
    if plan is not None:
        out.add(plan.allocator)
        if kind == "component":
            comp = component_of(name, plan)
            out |= {p.robot for p in plan.placements if p.component == comp}
    return out


def matching_events(
    names: Iterable[str], events: Iterable[Mapping[str, Any]]
) -> list[dict[str, Any]]:
    """The events that name any of `names` as a whole word (`eventlog.naming`), without
    duplicates (one event fetched from two robots), oldest first, the newest `MAX_EVENTS`."""
    names_it = naming(names)
    seen: set[tuple[Any, ...]] = set()
    out = []
    for e in events:
        if not names_it(e):
            continue
        key = (e.get("ts"), e.get("kind"), e.get("robot"), e.get("id"))
        if key in seen:
            continue
        seen.add(key)
        out.append(dict(e))
    out.sort(key=lambda e: e.get("ts") or 0.0)
    return out[-MAX_EVENTS:]


# -- checks against the thresholds --------------------------------------------------------


def _check(name: str, value: Any, op: str, bound: Any, unit: str = "") -> dict[str, Any]:
    """One value against one bound: ok, or not; None when the robot has no such value (it
    passes: no battery, no radio)."""
    if value is None:
        ok = True
    elif op == "<":
        ok = value < bound
    else:
        ok = value > bound
    return {"constraint": name, "value": value, "op": op, "bound": bound, "unit": unit, "ok": ok}


def robot_checks(metrics: Mapping[str, Any] | None, t: Thresholds) -> list[dict[str, Any]]:
    """A robot's metrics now against the Table I thresholds (the allocator also adds what an
    instance needs before comparing CPU and free memory)."""
    m = metrics or {}
    out = []
    if t.cpu_below_pct is not None:
        out.append(_check("cpu", m.get("cpu_pct"), "<", t.cpu_below_pct, "%"))
    if t.mem_free_above_bytes is not None:
        out.append(_check("memory", m.get("mem_free"), ">", t.mem_free_above_bytes, "B"))
    if t.battery_above_pct is not None:
        out.append(_check("battery", m.get("battery_pct"), ">", t.battery_above_pct, "%"))
    if t.rssi_above_dbm is not None:
        out.append(_check("rssi", m.get("rssi_dbm"), ">", t.rssi_above_dbm, "dBm"))
    return out


def link_checks(link: Mapping[str, Any] | None, t: Thresholds) -> list[dict[str, Any]]:
    """A link's measurement against the Table II bounds (none measured: each bound fails, as
    the allocator's constraints say)."""
    out = []
    for name, key, bound, unit in (
        ("delay", "rtt_ms", t.delay_below_ms, "ms"),
        ("jitter", "jitter_ms", t.jitter_below_ms, "ms"),
        ("loss", "loss", t.loss_below, ""),
    ):
        if bound is None:
            continue
        value = None if link is None else link.get(key)
        check = _check(name, value, "<", bound, unit)
        if link is None:
            check["ok"] = False
        out.append(check)
    return out


def pair_link(
    a: Mapping[str, Any] | None, b: Mapping[str, Any] | None, a_name: str, b_name: str
) -> tuple[dict[str, Any] | None, str]:
    """The link between two members as the allocator judges it: the worse of what each end
    lists of the other, else the worse of their typical links; with where it came from."""
    ends = []
    for doc, other in ((a, b_name), (b, a_name)):
        link = None if doc is None else (doc.get("links") or {}).get(other)
        if link is not None:
            ends.append(link)
    source = "measured"
    if not ends:
        source = "typical"
        for doc in (a, b):
            typical = None if doc is None else (doc.get("link_summary") or {}).get("typical")
            if typical is not None:
                ends.append(typical)
    if not ends:
        return None, "none"
    worst = {k: max(float(e.get(k) or 0.0) for e in ends) for k in ("rtt_ms", "jitter_ms", "loss")}
    return worst, source


# -- a component ----------------------------------------------------------------------------


def describe_component(
    name: str,
    plan: Plan,
    status: Mapping[str, Any],
    members: Sequence[Mapping[str, Any]],
    events: Iterable[Mapping[str, Any]],
) -> dict[str, Any]:
    """The describe document of a component (or of the component of an instance `name`)."""
    system = plan.system
    assert system is not None
    comp = system.component(component_of(name, plan))
    t = system.allocation.thresholds
    by_name = {str(m.get("name")): m for m in members}
    rows = [c for c in status.get("components") or [] if c.get("component") == comp.name]
    row: Mapping[str, Any] = rows[0] if rows else {}
    states = {row.get("instance"): row} | {s.get("instance"): s for s in row.get("standbys") or []}
    instances = []
    for p in plan.placements:
        if p.component != comp.name:
            continue
        st = states.get(p.instance, {})
        why = plan.why_of(p.instance)
        instances.append(
            {
                "instance": p.instance,
                "role": str(p.role),
                "mode": p.mode,
                "robot": p.robot,
                "state": st.get("state"),
                "since": st.get("since"),
                "why": None if why is None else why.to_json(),
            }
        )
    left_out = [w.to_json() for w in plan.why if w.component == comp.name and w.robot is None]
    wanted = comp.standby.same_robot + comp.standby.other_robots
    placed = sum(1 for i in instances if i["role"] == InstanceRole.STANDBY)
    conns = [
        c
        for c in status.get("connections") or []
        if str(c.get("from", "")).split(".")[0] == comp.name
        or str(c.get("to", "")).split(".")[0] == comp.name
    ]
    links = _peer_links(comp.name, plan, system, by_name, t)
    found = matching_events(subject_names(comp.name, "component", plan), events)
    doc = {
        "kind": "component",
        "component": comp.name,
        "target": comp.target,
        "system": system.name,
        "plan": {"epoch": plan.epoch, "version": plan.version, "allocator": plan.allocator},
        "strategy": system.allocation.strategy,
        "requires": {"cpu_pct": comp.requires.cpu_pct, "mem_bytes": comp.requires.mem_bytes},
        "thresholds": _thresholds_json(t),
        "instances": instances,
        "standbys": {
            "wanted": wanted,
            "placed": placed,
            "mode": comp.standby.mode,
            "left_out": left_out,
        },
        "connections": conns,
        "links": links,
        "events": found,
    }
    doc["warnings"] = _component_warnings(doc, by_name, t)
    return doc


def _peer_links(
    comp: str,
    plan: Plan,
    system: SystemDef,
    members: Mapping[str, Mapping[str, Any]],
    t: Thresholds,
) -> list[dict[str, Any]]:
    """Each connected component whose active runs on another robot: the link now, checked."""
    active = plan.active_of(comp)
    if active is None:
        return []
    peers: dict[str, None] = {}
    for c in system.connections:
        if c.from_component == comp:
            peers[c.to_component] = None
        elif c.to_component == comp:
            peers[c.from_component] = None
    out = []
    for peer in peers:
        other = plan.active_of(peer)
        if other is None or other.robot == active.robot:
            continue
        a, b = members.get(active.robot), members.get(other.robot)
        link, source = pair_link(a, b, active.robot, other.robot)
        out.append(
            {
                "peer": peer,
                "robots": [active.robot, other.robot],
                "link": link,
                "source": source,
                "checks": link_checks(link, t),
            }
        )
    return out


def _component_warnings(
    doc: Mapping[str, Any], members: Mapping[str, Mapping[str, Any]], t: Thresholds
) -> list[str]:
    """What is wrong with a component now (module docstring)."""
    out = []
    standbys = doc["standbys"]
    if standbys["placed"] < standbys["wanted"]:
        why = "; ".join(
            f"{w['instance']}: " + ", ".join(f"{r} ({x})" for r, x in w["ruled_out"])
            for w in standbys["left_out"]
        )
        out.append(
            f"no standby: the system asks for {standbys['wanted']}, the plan has "
            f"{standbys['placed']}" + (f"; no robot took {why}" if why else "")
        )
    for inst in doc["instances"]:
        robot = members.get(inst["robot"])
        state = robot.get("state") if robot is not None else None
        if (
            robot is None
            or state in (MemberState.DEAD, MemberState.LEFT, None)
            or (inst["state"] == "robot down")
        ):
            out.append(f"{inst['instance']}: its robot {inst['robot']} is down ({state or 'gone'})")
            continue
        wanted = inst["role"] == InstanceRole.ACTIVE
        if wanted and inst["state"] not in (_ACTIVE, None):
            out.append(f"{inst['instance']}: {inst['state']}, not ACTIVE")
        if inst["role"] == InstanceRole.STANDBY and inst["state"] in ("pending", None):
            out.append(f"standby {inst['instance']} on {inst['robot']} is not running yet")
        for check in robot_checks(robot.get("metrics"), t):
            if check["constraint"] in ("battery", "rssi") and not check["ok"]:
                out.append(
                    f"{inst['instance']}: {inst['robot']} fails {check['constraint']} now: "
                    f"{check['value']}{check['unit']} not {check['op']} "
                    f"{check['bound']}{check['unit']}"
                )
    for link in doc["links"]:
        for check in link["checks"]:
            if not check["ok"]:
                value = "not measured" if check["value"] is None else f"{check['value']:.4g}"
                out.append(
                    f"link to {link['peer']} ({' - '.join(link['robots'])}) fails "
                    f"{check['constraint']} now: {value} not < {check['bound']:g}{check['unit']}"
                )
    for c in doc["connections"]:
        lost = c.get("lost_per_s")
        if lost:
            out.append(f"{c.get('from')} -> {c.get('to')} drops {lost} frames/s (full buffers)")
    overflows = [e for e in doc["events"] if e.get("kind") == EventKind.PORT_OVERFLOW]
    if overflows:
        last = overflows[-1]
        detail = json.dumps(last.get("detail"), sort_keys=True)
        out.append(f"port.overflow on {last.get('robot')}: {detail}")
    out += refused_warnings(doc["events"])
    return out


def refused_warnings(events: Iterable[Mapping[str, Any]]) -> list[str]:
    """One warning per connection whose latest refusal event (oldest first in `events`) is not
    followed by its `conn.accepted`: its receiver refuses it, so it sends nothing."""
    latest: dict[tuple[Any, Any], Mapping[str, Any]] = {}
    for e in events:
        if e.get("kind") in (EventKind.CONN_REFUSED, EventKind.CONN_ACCEPTED):
            d = e.get("detail") or {}
            latest[(e.get("robot"), d.get("conn"))] = e
    out = []
    for e in latest.values():
        if e.get("kind") == EventKind.CONN_REFUSED:
            d = e.get("detail") or {}
            out.append(
                f"{d.get('sender')} -> {d.get('to')} {d.get('port')} (connection "
                f"{d.get('conn')} on {e.get('robot')}) is refused by its receiver: "
                f"{d.get('error')}"
            )
    return out


def _thresholds_json(t: Thresholds) -> dict[str, Any]:
    """The allocation thresholds that are set (Table I and II)."""
    fields = {
        "cpu_below_pct": t.cpu_below_pct,
        "mem_free_above_bytes": t.mem_free_above_bytes,
        "battery_above_pct": t.battery_above_pct,
        "rssi_above_dbm": t.rssi_above_dbm,
        "jitter_below_ms": t.jitter_below_ms,
        "distance_below_m": t.distance_below_m,
        "loss_below": t.loss_below,
        "delay_below_ms": t.delay_below_ms,
    }
    return {k: v for k, v in fields.items() if v is not None}


# -- a robot --------------------------------------------------------------------------------


def describe_robot(
    name: str,
    plan: Plan | None,
    status: Mapping[str, Any],
    members: Sequence[Mapping[str, Any]],
    events: Iterable[Mapping[str, Any]],
) -> dict[str, Any]:
    """The describe document of a robot."""
    member = next((m for m in members if m.get("name") == name), None)
    t = Thresholds() if plan is None or plan.system is None else plan.system.allocation.thresholds
    allocator = (status.get("allocator") or {}).get("name")
    summary = (member or {}).get("link_summary") or {}
    placed = []
    for p in [] if plan is None else plan.on_robot(name):
        why = plan.why_of(p.instance) if plan is not None else None
        placed.append(
            {
                "instance": p.instance,
                "component": p.component,
                "role": str(p.role),
                "mode": p.mode,
                "how": None if why is None else why.how,
            }
        )
    running = [
        {k: i.get(k) for k in ("name", "component", "state", "role", "cpu_pct", "rss", "out_lost")}
        for i in (member or {}).get("instances") or []
    ]
    doc: dict[str, Any] = {
        "kind": "robot",
        "robot": name,
        "state": None if member is None else member.get("state"),
        "since": None if member is None else member.get("since"),
        "allocator": allocator == name,
        "metrics": None if member is None else member.get("metrics"),
        "thresholds": _thresholds_json(t),
        "checks": robot_checks(None if member is None else member.get("metrics"), t),
        "link": {
            "typical": summary.get("typical"),
            "checks": link_checks(summary.get("typical"), t) if summary.get("typical") else [],
            "past_bounds": summary.get("listed") or {},
        },
        "placed": placed,
        "running": running,
        "events": matching_events([name], events),
    }
    warnings = []
    if member is None or member.get("state") in (MemberState.DEAD, MemberState.LEFT):
        state = "unknown" if member is None else member.get("state")
        warnings.append(f"{name} is {state}: its placements are moved by the allocator")
    for check in doc["checks"]:
        if not check["ok"]:
            warnings.append(
                f"{check['constraint']} {check['value']}{check['unit']} not {check['op']} "
                f"{check['bound']}{check['unit']}: the allocator places nothing more here"
            )
    for i in running:
        if i.get("out_lost"):
            warnings.append(f"{i['name']} drops {i['out_lost']} frames/s (full buffers)")
    doc["warnings"] = warnings
    return doc
