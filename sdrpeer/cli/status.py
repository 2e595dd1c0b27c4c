"""Pure text rendering of the deployment status and of `sdrpeer top`'s screen.

Nothing here does I/O. `format_status` is `sdrpeer status`: the allocator, the plan, a table of
components (robot, state, since, standbys, traffic) and the connections with their traffic (and
a line for each sender whose receivers refuse some of its connections), in colour on a
terminal; once a constraint applies to a running placement, each component's
compliance (its Table I/II constraints re-checked while it runs) and a table of the
constraints past their bound.
`format_top` is one screen of `sdrpeer top`, built from one live sample of
the agent's stream (`sdrpeer.dashboard.feed`): robots with their metrics and link summary, then
components.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

from sdrpeer.cli.format import (
    MISSING,
    STATE_COLORS,
    human_bytes,
    human_dbm,
    human_ms,
    human_percent,
    paint,
    render_table,
)
from sdrpeer.record.robot import state_to_wire
from sdrpeer.vocabulary import LifecycleState, ProcessState

COMPONENT_COLORS = {
    state_to_wire(LifecycleState.ACTIVE): "32",
    state_to_wire(LifecycleState.INACTIVE): "36",
    state_to_wire(LifecycleState.ERROR): "31",
    state_to_wire(ProcessState.FAILED): "31",
    "pending": "33",
    state_to_wire(ProcessState.STARTING): "33",
    state_to_wire(ProcessState.UPDATING): "33",
    "robot down": "31",
    "unplaced": "31",
    "cold": "90",
}
STATUS_COLUMNS = ("COMPONENT", "ROBOT", "STATE", "SINCE", "SENDS", "STANDBYS")
COMPLIANCE_COLUMNS = ("COMPONENT", "CONSTRAINT", "OF", "VALUE", "BOUND", "STATE", "SINCE")
ROBOT_COLUMNS = ("ROBOT", "STATE", "ROLE", "CPU", "MEM-FREE", "BATTERY", "RSSI", "RTT", "LOSS")


def _rate(value: Any) -> str:
    if not isinstance(value, int | float) or isinstance(value, bool):
        return MISSING
    return f"{human_bytes(value)}/s"


def _clock(ts: Any, tz_local: bool = True) -> str:
    if not isinstance(ts, int | float):
        return MISSING
    return time.strftime("%H:%M:%S", time.localtime(ts) if tz_local else time.gmtime(ts))


def _state(state: Any, color: bool) -> str:
    text = str(state or MISSING)
    return paint(text, COMPONENT_COLORS.get(text, ""), color)


def _sends(doc: Mapping[str, Any]) -> dict[str, Any]:
    """Component -> bytes/s its active instance sends: its own figure (every OutPort, and a
    ROS 2 node's topics), else its connections' traffic."""
    out: dict[str, Any] = {}
    for c in doc.get("connections") or []:
        out[str(c.get("from", "")).split(".")[0]] = c.get("bytes_per_s")
    for comp in doc.get("components") or []:
        if comp.get("sends_bytes_per_s"):
            out[str(comp.get("component"))] = comp["sends_bytes_per_s"]
    return out


def _lost(conn: Mapping[str, Any], color: bool) -> str:
    """Frames/s the sender's connections lose to full buffers (red when any)."""
    lost = conn.get("lost_per_s")
    if lost is None:
        return MISSING
    return paint(f"{lost}/s", "31", color) if lost else "0"


def _refused(conns: Sequence[Mapping[str, Any]], color: bool) -> list[str]:
    """A line per sending component whose receivers refuse some of its connections now (red):
    they carry nothing (`sdrpeer describe` says why). `refused` is the sending instance's, like
    `lost_per_s`: said once per component."""
    out: list[str] = []
    said: set[str] = set()
    for c in conns:
        sender, n = str(c.get("from")).split(".")[0], c.get("refused")
        if sender in said or isinstance(n, bool) or not isinstance(n, int) or n <= 0:
            continue
        said.add(sender)
        text = f"{sender}: {n} connection(s) refused by the receiver (sdrpeer describe {sender})"
        out.append(paint(text, "31", color))
    return out


def _quantity(constraint: Any, value: Any) -> str:
    """A compliance value or bound in its constraint's unit (loss is a fraction)."""
    if not isinstance(value, int | float) or isinstance(value, bool):
        return MISSING
    if constraint == "loss":
        return f"{100 * value:.1f}%"
    if constraint in ("cpu", "battery"):
        return human_percent(value)
    if constraint == "memory":
        return human_bytes(value)
    if constraint == "rssi":
        return human_dbm(value)
    if constraint in ("delay", "jitter"):
        return human_ms(value)
    return f"{value:.4g}m" if constraint == "distance" else f"{value:.4g}"


def _compliance(doc: Mapping[str, Any], component: Any, color: bool) -> str:
    """The COMPLIANCE cell: ok, or the constraints violated (red) or past their bound for less
    than the sustain (yellow); - when no constraint applies."""
    rows = [r for r in doc.get("compliance") or [] if r.get("component") == component]
    if not rows:
        return MISSING
    bad = [r["constraint"] for r in rows if r.get("state") == "violated"]
    if bad:
        return paint("violated: " + ",".join(dict.fromkeys(bad)), "31", color)
    holding = [r["constraint"] for r in rows if r.get("state") == "holding"]
    if holding:
        return paint("holding: " + ",".join(dict.fromkeys(holding)), "33", color)
    return "ok"


def format_status(doc: Mapping[str, Any], *, color: bool = False, local: bool = True) -> str:
    """The `sdrpeer status` text (`local`: times in the local zone, else UTC)."""
    alloc = doc.get("allocator") or {}
    plan = doc.get("plan")
    lines = [f"allocator: {alloc.get('name') or '(none yet)'} (epoch {alloc.get('epoch')})"]
    if plan is None:
        lines.append("no system deployed")
        return "\n".join(lines)
    lines.append(
        f"system: {plan.get('system') or '(undeployed)'}  plan {plan['epoch']}.{plan['version']}"
        f" by {plan.get('allocator')}"
    )
    sends = _sends(doc)
    checked = bool(doc.get("compliance"))  # a COMPLIANCE column once any constraint applies
    rows = []
    for c in doc.get("components") or []:
        standbys = ", ".join(
            f"{s.get('robot')}:{_state(s.get('state'), color)}"
            + ("/cold" if s.get("mode") == "cold" and s.get("state") != "cold" else "")
            for s in c.get("standbys") or []
        )
        rows.append(
            [
                str(c.get("component")),
                str(c.get("robot") or MISSING),
                _state(c.get("state"), color),
                _clock(c.get("since"), local),
                _rate(sends.get(str(c.get("component")))),
                standbys or MISSING,
            ]
        )
        if checked:
            rows[-1].append(_compliance(doc, c.get("component"), color))
    lines.append(render_table(STATUS_COLUMNS + (("COMPLIANCE",) if checked else ()), rows))
    conns = doc.get("connections") or []
    if conns:
        lines.append("")
        edges = [
            [str(c.get("from")), str(c.get("to")), _rate(c.get("bytes_per_s")), _lost(c, color)]
            for c in conns
        ]
        lines.append(render_table(("FROM", "TO", "TRAFFIC", "LOST"), edges))
        lines += _refused(conns, color)
    past = [r for r in doc.get("compliance") or [] if r.get("state") in ("violated", "holding")]
    if past:
        lines.append("")
        cells = [
            [
                str(r.get("component")),
                str(r.get("constraint")),
                str(r.get("subject")),
                _quantity(r.get("constraint"), r.get("value")),
                f"{r.get('must_be')} {_quantity(r.get('constraint'), r.get('bound'))}",
                paint(str(r.get("state")), "31" if r.get("state") == "violated" else "33", color),
                _clock(r.get("since"), local),
            ]
            for r in past
        ]
        lines.append(render_table(COMPLIANCE_COLUMNS, cells))
    return "\n".join(lines)


def robot_rows(
    members: Sequence[Mapping[str, Any]], leader: str | None, *, color: bool
) -> list[list[str]]:
    """ROBOT_COLUMNS cells of each robot of a live sample."""
    rows = []
    for m in members:
        metrics = m.get("metrics") or {}
        link = m.get("link") or {}
        state = str(m.get("state", MISSING))
        loss = link.get("loss")
        rows.append(
            [
                str(m.get("name")),
                paint(state, STATE_COLORS.get(state, ""), color),
                "allocator" if m.get("name") == leader else "",
                human_percent(metrics.get("cpu_pct")),
                human_bytes(metrics.get("mem_free")),
                human_percent(metrics.get("battery_pct")),
                human_dbm(metrics.get("rssi_dbm")),
                human_ms(link.get("rtt_ms")),
                MISSING if loss is None else human_percent(100 * loss),
            ]
        )
    return rows


def format_top(sample: Mapping[str, Any], *, color: bool = False, local: bool = True) -> str:
    """One screen of `sdrpeer top` (`local`: times in the local zone, else UTC)."""
    status = sample.get("status") or {}
    leader = (status.get("allocator") or {}).get("name")
    members = sample.get("members") or []
    head = (
        f"sdrpeer top — {sample.get('robot')} at {_clock(sample.get('ts'), local)}"
        f"  ·  {len(members)} robots  ·  allocator {leader or '(none yet)'}"
    )
    parts = [head, "", render_table(ROBOT_COLUMNS, robot_rows(members, leader, color=color)), ""]
    if status:
        parts.append(format_status(status, color=color, local=local))
    return "\n".join(parts)
