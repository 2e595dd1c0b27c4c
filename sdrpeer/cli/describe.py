"""`sdrpeer describe COMPONENT|ROBOT`: the text of one `GET /v1/describe/{name}` (pure).

How it works: the agent builds the document (`sdrpeer.deploy.describe`); this module only lays it
out the way `kubectl describe` does: a header of fields, then sections (instances with the
allocator's explanation, standbys, links, connections, events), warnings last, in colour on a
terminal.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from typing import Any

from sdrpeer.cli.format import MISSING, human_bytes, paint

HOW_TEXT = {
    "kept": "kept where it was (it still passes every constraint)",
    "pinned": "pinned to this robot by the system file",
    "standby_promoted": "its running standby here became the active",
    "preferred": "the first robot of its prefer list that passed",
    "ranked": "the first robot in the strategy's order that passed",
    "same_robot": "a standby on its active's robot",
    "held": "held here by the disconnect policy (its robot is lost)",
    "left_out": "no robot took it",
}


def _clock(ts: Any) -> str:
    if not isinstance(ts, int | float):
        return MISSING
    return time.strftime("%H:%M:%S", time.localtime(ts))


def _plan(pair: Sequence[Any] | None) -> str:
    return MISSING if not pair else f"{pair[0]}.{pair[1]}"


def _value(v: Any, unit: str) -> str:
    if v is None:
        return "none"
    if unit == "B":
        return human_bytes(v)
    if unit == "":
        return f"{100 * float(v):.3g}%" if isinstance(v, float) and v <= 1 else f"{v}"
    return f"{v:.4g}{unit}" if isinstance(v, float) else f"{v}{unit}"


def _check(c: Mapping[str, Any], color: bool) -> str:
    unit = str(c.get("unit") or "")
    verdict = paint("ok", "32", color) if c.get("ok") else paint("FAILS", "31", color)
    bound = _value(c.get("bound"), unit)
    return f"{c.get('constraint')} {_value(c.get('value'), unit)} {c.get('op')} {bound} {verdict}"


def _why(why: Mapping[str, Any] | None, indent: str) -> list[str]:
    if why is None:
        return [f"{indent}why:        (no explanation: the plan came from an older allocator)"]
    how = str(why.get("how"))
    lines = [f"{indent}how:        {how}: {HOW_TEXT.get(how, how)}"]
    decided = f"plan {_plan(why.get('decided_in'))} ({why.get('reason') or 'no reason'})"
    if why.get("checked_in") != why.get("decided_in"):
        decided += f"; checked again in plan {_plan(why.get('checked_in'))}"
    lines.append(f"{indent}decided in: {decided}")
    ruled = why.get("ruled_out") or []
    if ruled:
        label = "ruled out: " if how != "left_out" else "refused by:"
        for k, (robot, reason) in enumerate(ruled):
            lines.append(f"{indent}{label if k == 0 else ' ' * 11} {robot}: {reason}")
        if why.get("more_ruled_out"):
            lines.append(f"{indent}{' ' * 12}... and {why['more_ruled_out']} more robots")
    if why.get("checked"):
        lines.append(f"{indent}passed:     {'; '.join(why['checked'])}")
    if why.get("scores"):
        scores = ", ".join(f"{r} {s:.3f}" for r, s in why["scores"])
        lines.append(f"{indent}scores:     {scores}")
    return lines


def _events(events: Sequence[Mapping[str, Any]]) -> list[str]:
    if not events:
        return ["Events:       none"]
    lines = ["Events (newest last):"]
    for e in events:
        detail = ", ".join(f"{k}={v}" for k, v in sorted((e.get("detail") or {}).items()))
        lines.append(f"  {_clock(e.get('ts'))}  {e.get('robot')}  {e.get('kind')}  {detail}")
    return lines


def _warnings(doc: Mapping[str, Any], color: bool) -> list[str]:
    warnings = doc.get("warnings") or []
    if not warnings:
        return ["Warnings:     none"]
    return ["Warnings:"] + [f"  {paint('!', '31', color)} {w}" for w in warnings]


def _asked(doc: Mapping[str, Any]) -> list[str]:
    asked = doc.get("asked") or {}
    if not asked.get("unreachable"):
        return []
    return [f"(events of {', '.join(asked['unreachable'])} unknown: not reachable)"]


def format_component(doc: Mapping[str, Any], *, color: bool = False) -> str:
    """The text of a component's describe document."""
    plan = doc.get("plan") or {}
    req = doc.get("requires") or {}
    lines = [
        f"Component:    {doc.get('component')} ({doc.get('target')})",
        f"System:       {doc.get('system')}  plan {plan.get('epoch')}.{plan.get('version')} "
        f"by {plan.get('allocator')}  strategy {doc.get('strategy')}",
        f"Requires:     cpu {req.get('cpu_pct')}%  memory {human_bytes(req.get('mem_bytes') or 0)}",
        "Thresholds:   "
        + (", ".join(f"{k}={v}" for k, v in (doc.get("thresholds") or {}).items()) or "none"),
        "Instances:",
    ]
    for inst in doc.get("instances") or []:
        lines.append(
            f"  {inst.get('instance')}  {inst.get('role')}  on {inst.get('robot')}  "
            f"{inst.get('state') or MISSING} since {_clock(inst.get('since'))}"
        )
        lines += _why(inst.get("why"), "    ")
    sb = doc.get("standbys") or {}
    lines.append(
        f"Standbys:     {sb.get('placed')} of {sb.get('wanted')} placed ({sb.get('mode')})"
    )
    for w in sb.get("left_out") or []:
        lines.append(f"  {w.get('instance')}  left out")
        lines += _why(w, "    ")
    links = doc.get("links") or []
    if links:
        lines.append("Links now (Table II):")
        for link in links:
            checks = ", ".join(_check(c, color) for c in link.get("checks") or []) or "no bound"
            robots = " - ".join(link.get("robots") or [])
            lines.append(f"  to {link.get('peer')} ({robots}, {link.get('source')}): {checks}")
    conns = doc.get("connections") or []
    if conns:
        lines.append("Connections:")
        for c in conns:
            rate = c.get("bytes_per_s")
            sends = MISSING if rate is None else f"{human_bytes(rate)}/s"
            lines.append(f"  {c.get('from')} -> {c.get('to')}  {sends}  lost {c.get('lost_per_s')}")
    lines += _events(doc.get("events") or [])
    lines += _warnings(doc, color)
    return "\n".join(lines + _asked(doc))


def format_robot(doc: Mapping[str, Any], *, color: bool = False) -> str:
    """The text of a robot's describe document."""
    role = "  (allocator)" if doc.get("allocator") else ""
    lines = [
        f"Robot:        {doc.get('robot')}{role}",
        f"State:        {doc.get('state') or 'unknown'} since {_clock(doc.get('since'))}",
    ]
    checks = doc.get("checks") or []
    lines.append(
        "Table I now:  " + ("; ".join(_check(c, color) for c in checks) or "no thresholds")
    )
    link = doc.get("link") or {}
    link_checks = link.get("checks") or []
    lines.append(
        "Table II now: "
        + ("; ".join(_check(c, color) for c in link_checks) or "no bounds or no link")
        + " (its typical link)"
    )
    for peer, stats in sorted((link.get("past_bounds") or {}).items()):
        lines.append(f"  past the bounds to {peer}: {stats}")
    lines.append("Placed here:")
    for p in doc.get("placed") or []:
        lines.append(
            f"  {p.get('instance')}  {p.get('component')}  {p.get('role')}/{p.get('mode')}  "
            f"{p.get('how') or ''}"
        )
    lines.append("Running here:")
    for i in doc.get("running") or []:
        lines.append(f"  {i.get('name')}  {i.get('component')}  {i.get('state')}  {i.get('role')}")
    lines += _events(doc.get("events") or [])
    lines += _warnings(doc, color)
    return "\n".join(lines + _asked(doc))


def format_describe(doc: Mapping[str, Any], *, color: bool = False) -> str:
    """`sdrpeer describe`'s text for either kind of document."""
    if doc.get("kind") == "robot":
        return format_robot(doc, color=color)
    return format_component(doc, color=color)
