"""Pure text rendering for the `sdrpeer` command: tables, human units, state colours.

Nothing here does I/O; callers decide whether to colour (`want_color`) and where to print.
"""

from __future__ import annotations

import json
import re
from collections.abc import Mapping, Sequence
from datetime import datetime, tzinfo
from typing import Any

from sdrpeer.eventlog import EventKind
from sdrpeer.vocabulary import LifecycleState, MemberState, ProcessState

STATE_COLORS: dict[str, str] = {
    MemberState.ALIVE: "32",
    MemberState.SUSPECT: "33",
    MemberState.DEAD: "31",
    MemberState.LEFT: "90",
}
MEMBER_COLUMNS = (
    "NAME",
    "ADDR",
    "STATE",
    "INC",
    "CPU",
    "MEM-FREE",
    "BATTERY",
    "RSSI",
    "POS",
    "LINKS",
)
_ANSI = re.compile(r"\x1b\[[0-9;]*m")
MISSING = "-"


def want_color(is_tty: bool, env: Mapping[str, str]) -> bool:
    """Colour only on a terminal, and never when NO_COLOR is set (https://no-color.org)."""
    return is_tty and not env.get("NO_COLOR") and env.get("TERM") != "dumb"


def paint(text: str, code: str, color: bool) -> str:
    """`text` wrapped in an ANSI SGR code when `color` is on."""
    return f"\x1b[{code}m{text}\x1b[0m" if color and code else text


def visible_len(text: str) -> int:
    """Length of `text` as shown on a terminal (ANSI codes take no room)."""
    return len(_ANSI.sub("", text))


def _num(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


def human_bytes(n: Any) -> str:
    """Bytes with one decimal in powers of 1000: 3_200_000_000 -> '3.2GB', 512 -> '512B'."""
    value = _num(n)
    if value is None:
        return MISSING
    for unit in ("B", "KB", "MB", "GB", "TB"):
        if abs(value) < 1000 or unit == "TB":
            return f"{value:.0f}{unit}" if unit == "B" else f"{value:.1f}{unit}"
        value /= 1000
    raise AssertionError("unreachable")  # pragma: no cover


def human_percent(pct: Any) -> str:
    """A percentage: 87.4 -> '87%'."""
    value = _num(pct)
    return MISSING if value is None else f"{value:.0f}%"


def human_dbm(dbm: Any) -> str:
    """Signal strength: -47 -> '-47.0dBm'."""
    value = _num(dbm)
    return MISSING if value is None else f"{value:.1f}dBm"


def human_ms(ms: Any) -> str:
    """Milliseconds, short: 0.42 -> '0.4ms', 12.3 -> '12ms'."""
    value = _num(ms)
    if value is None:
        return MISSING
    return f"{value:.1f}ms" if value < 10 else f"{value:.0f}ms"


def human_pos(pos: Any) -> str:
    """A position [x, y] in metres: '3.0,0.0'."""
    if not isinstance(pos, list | tuple) or len(pos) < 2:
        return MISSING
    coords = [_num(c) for c in pos[:2]]
    if None in coords:
        return MISSING
    return ",".join(f"{c:.1f}" for c in coords if c is not None)


def human_seconds(seconds: Any) -> str:
    """A duration: 75 -> '1m15s', 3.2 -> '3.2s', 7300 -> '2h01m'."""
    value = _num(seconds)
    if value is None:
        return MISSING
    if value < 60:
        return f"{value:.1f}s"
    minutes, secs = divmod(int(value), 60)
    if minutes < 60:
        return f"{minutes}m{secs:02d}s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours}h{minutes:02d}m"


def format_link(peer: str, link: Mapping[str, Any]) -> str:
    """One link, compact: 'robot-2 0.4ms/0.1ms/0%' (rtt/jitter/loss)."""
    loss = _num(link.get("loss"))
    loss_text = MISSING if loss is None else f"{loss * 100:.0f}%"
    rtt, jitter = human_ms(link.get("rtt_ms")), human_ms(link.get("jitter_ms"))
    return f"{peer} {rtt}/{jitter}/{loss_text}"


def format_links(links: Mapping[str, Mapping[str, Any]] | None) -> str:
    """Every link of a member, sorted by peer, comma-separated."""
    if not links:
        return MISSING
    return ", ".join(format_link(peer, links[peer]) for peer in sorted(links))


def format_link_summary(member: Mapping[str, Any]) -> str:
    """A member's links in one cell: its typical link over its peers, then the links past the
    bounds ('typical 0.4ms/0.1ms/0% of 49; robot-7 80ms/2.0ms/0%'); the links themselves
    when there is no summary."""
    summary = member.get("link_summary")
    if not isinstance(summary, Mapping):
        return format_links(member.get("links"))
    typical = summary.get("typical")
    if not isinstance(typical, Mapping):
        return MISSING
    text = format_link("typical", typical) + f" of {summary.get('peers', 0)}"
    listed = summary.get("listed") or {}
    if listed:
        text += "; " + format_links(listed)
        more = int(summary.get("bad") or 0) - len(listed)
        if more > 0:
            text += f" and {more} more"
    return text


def format_metrics(metrics: Mapping[str, Any]) -> str:
    """A metrics dict on one line: 'cpu 1%, mem-free 4.0GB/4.0GB, battery 30%, rssi -55.3dBm'."""
    parts = [
        f"cpu {human_percent(metrics.get('cpu_pct'))}",
        f"mem-free {human_bytes(metrics.get('mem_free'))}/{human_bytes(metrics.get('mem_total'))}",
        f"battery {human_percent(metrics.get('battery_pct'))}",
        f"rssi {human_dbm(metrics.get('rssi_dbm'))}",
        f"pos {human_pos(metrics.get('pos'))}",
    ]
    return ", ".join(parts)


def member_row(member: Mapping[str, Any], *, color: bool) -> list[str]:
    """The cells of one member in MEMBER_COLUMNS order."""
    metrics = member.get("metrics") or {}
    state = str(member.get("state", MISSING))
    return [
        str(member.get("name", MISSING)),
        str(member.get("addr") or MISSING),
        paint(state, STATE_COLORS.get(state, ""), color),
        str(member.get("incarnation", MISSING)),
        human_percent(metrics.get("cpu_pct")),
        human_bytes(metrics.get("mem_free")),
        human_percent(metrics.get("battery_pct")),
        human_dbm(metrics.get("rssi_dbm")),
        human_pos(metrics.get("pos")),
        format_link_summary(member),
    ]


def render_table(headers: Sequence[str], rows: Sequence[Sequence[str]]) -> str:
    """Left-aligned columns separated by two spaces; no trailing spaces; ANSI-aware widths."""
    widths = [len(h) for h in headers]
    for row in rows:
        for i, cell in enumerate(row):
            widths[i] = max(widths[i], visible_len(cell))
    lines = []
    for row in [list(headers), *rows]:
        cells = [cell + " " * (widths[i] - visible_len(cell)) for i, cell in enumerate(row)]
        lines.append("  ".join(cells).rstrip())
    return "\n".join(lines)


def format_members(members: Sequence[Mapping[str, Any]], *, color: bool = False) -> str:
    """The `sdrpeer members` table."""
    return render_table(MEMBER_COLUMNS, [member_row(m, color=color) for m in members])


def _launchers(launchers: Mapping[str, Any]) -> str:
    """`python, ros2` and, after it, each launcher configured but not offered with why."""
    text = ", ".join(launchers.get("offered") or []) or "none"
    for name, why in (launchers.get("not_offered") or {}).items():
        text += f"; not {name}: {why}"
    return text


def format_agent(agent: Mapping[str, Any]) -> str:
    """The `sdrpeer agent-info` summary: one `key: value` line per counter group."""
    messages = agent.get("messages") or {}
    members = agent.get("members") or {}
    rejected = agent.get("rejected") or {}
    rejected_text = ", ".join(f"{k}={rejected[k]}" for k in sorted(rejected)) or "none"
    rates = (
        f"{human_bytes(messages.get('bytes_in_per_s'))}/s in, "
        f"{human_bytes(messages.get('bytes_out_per_s'))}/s out"
    )
    pairs = [
        ("name", agent.get("name", MISSING)),
        ("version", agent.get("version", MISSING)),
        ("gossip", agent.get("addr", MISSING)),
        ("api", agent.get("api", MISSING)),
        ("uptime", human_seconds(agent.get("uptime_s"))),
        ("preset", agent.get("preset", MISSING)),
        ("security", "INSECURE (no cluster key)" if agent.get("insecure") else "cluster key"),
        ("launchers", _launchers(agent.get("launchers") or {})),
        ("health score", agent.get("health_score", MISSING)),
        (
            "members",
            ", ".join(f"{s} {members.get(s, 0)}" for s in MemberState),
        ),
        (
            "messages",
            f"{messages.get('in', 0)} in, {messages.get('out', 0)} out "
            f"({human_bytes(messages.get('bytes_in'))} in, "
            f"{human_bytes(messages.get('bytes_out'))} out; {rates})",
        ),
        ("rejected", rejected_text),
    ]
    width = max(len(k) for k, _ in pairs)
    return "\n".join(f"{k + ':':<{width + 1}} {v}" for k, v in pairs)


EVENT_COLORS: dict[str, str] = {
    EventKind.MEMBER_JOIN: "32",
    EventKind.MEMBER_ALIVE: "32",
    EventKind.MEMBER_SUSPECT: "33",
    EventKind.MEMBER_DEAD: "31",
    EventKind.MEMBER_LEFT: "90",
    EventKind.MEMBER_REAPED: "90",
    EventKind.TRAP: "35",
    EventKind.WIRE_REJECTED: "31",
}


def format_event(event: Mapping[str, Any], *, color: bool = False, tz: tzinfo | None = None) -> str:
    """One event log line: '  12 14:03:22.125 member.suspect  robot-2  {"by": "robot-3"}'."""
    ts = _num(event.get("ts"))
    when = (
        datetime.fromtimestamp(ts, tz).strftime("%H:%M:%S.%f")[:-3] if ts is not None else MISSING
    )
    kind = str(event.get("kind", MISSING))
    detail = event.get("detail") or {}
    detail_text = json.dumps(detail, sort_keys=True, separators=(", ", ": ")) if detail else ""
    line = (
        f"{event.get('id', MISSING):>5} {when} "
        f"{paint(f'{kind:<15}', EVENT_COLORS.get(kind, ''), color)} "
        f"{event.get('robot', MISSING)!s:<9} {detail_text}"
    )
    return line.rstrip()


INSTANCE_COLUMNS = ("NAME", "COMPONENT", "STATE", "ROLE", "PID", "CPU", "RSS", "RESTARTS", "SINCE")
INSTANCE_COLORS: dict[str, str] = {
    LifecycleState.ACTIVE: "32",
    LifecycleState.INACTIVE: "36",
    LifecycleState.ERROR: "31",
    ProcessState.FAILED: "31",
    ProcessState.BACKOFF: "33",
}


def format_instances(
    instances: Sequence[Mapping[str, Any]], *, now: float, color: bool = False
) -> str:
    """The `sdrpeer instances` table; SINCE is how long ago the state last changed."""
    rows = []
    for i in instances:
        state = str(i.get("state", MISSING))
        since = _num(i.get("since"))
        rows.append(
            [
                str(i.get("name", MISSING)),
                str(i.get("component", MISSING)),
                paint(state, INSTANCE_COLORS.get(state, ""), color),
                str(i.get("role", MISSING)),
                str(i.get("pid") or MISSING),
                human_percent(i.get("cpu_pct")),
                human_bytes(i.get("rss")),
                str(i.get("restarts", MISSING)),
                MISSING if since is None else human_seconds(max(0.0, now - since)),
            ]
        )
    lines = [render_table(INSTANCE_COLUMNS, rows)]
    for i in instances:  # why a connection sends nothing: its receiver refuses it
        for c in i.get("connections") or []:
            refused = c.get("refused")
            if isinstance(refused, Mapping):
                lines.append(
                    paint(
                        f"{i.get('name')}: connection {c.get('id')} refused by its receiver "
                        f"({refused.get('count')}x): {refused.get('error')}",
                        "31",
                        color,
                    )
                )
    return "\n".join(lines)
