"""The paper's Figs. 4-6 from a recorded timeline, as PNG files (matplotlib, Agg).

How it works: `render_figures` reads the lines of a timeline (sdrpeer/demo/timeline.py) and
draws three figures with matplotlib's object API (`Figure`, no pyplot, so no global backend
state; matplotlib is imported inside the function, so nothing else in sdrpeer needs it):
- fig4_free_memory.png: one panel per robot, free memory in MB (1 MB = 10^6 bytes) from the
  "sample" lines, with Table V's allocation threshold (500MB) and Table VI's memory-shortage
  threshold (200MB) as horizontal lines; a gap of more than `GAP_S` between samples (an agent
  that was down) breaks the curve;
- fig5_rssi.png: the RSSI of `rssi_robot` with Table VI's threshold (-52.5 dBm);
- fig6_states.png: one row per (robot, instance), a bar where the instance is ACTIVE (hatched
  while it is an active standby), lighter where it is INACTIVE, from the "state" lines.
Every panel gets the "mark" lines: allocation as orange dashed verticals, recovery as purple
dash-dot ones (the paper's), faults as grey dotted ones. Time is seconds since the recorder
started. `summary_table` is the same story as text.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sdrpeer.demo.query import Timeline
from sdrpeer.record.robot import state_from_wire
from sdrpeer.vocabulary import InstanceRole, LifecycleState

if TYPE_CHECKING:
    from matplotlib.axes import Axes

PAPER_THRESHOLDS: dict[str, float] = {
    "allocation_mem_free": 500e6,
    "shortage_mem_free": 200e6,
    "rssi": -52.5,
}
"""Table V: free memory the allocator keeps (bytes); Table VI: shortage (bytes), RSSI (dBm)."""
MARK_STYLES: dict[str, dict[str, Any]] = {
    "allocation": {"color": "tab:orange", "linestyle": "--", "label": "dynamic module allocation"},
    "recovery": {"color": "tab:purple", "linestyle": "-.", "label": "automatic recovery"},
    "fault": {"color": "0.45", "linestyle": ":", "label": "fault injected"},
}
STATE_STYLES: dict[str, dict[str, Any]] = {
    LifecycleState.ACTIVE: {"facecolors": "tab:blue", "label": LifecycleState.ACTIVE},
    InstanceRole.STANDBY: {
        "facecolors": "#9ecae1",
        "hatch": "///",
        "edgecolor": "tab:blue",
        "label": "ACTIVE (standby)",
    },
    LifecycleState.INACTIVE: {"facecolors": "#c6dbef", "label": LifecycleState.INACTIVE},
    LifecycleState.ERROR: {"facecolors": "tab:red", "label": LifecycleState.ERROR},
    "other": {"facecolors": "0.85", "label": "starting / stopping"},
}
GAP_S = 2.0
Rows = dict[tuple[str, str], tuple[str, dict[str, list[tuple[float, float]]]]]
"""Fig. 6's rows: (robot, instance) -> (component, style -> [(start, width)])."""
MB = 1e6


def render_figures(
    timeline: list[dict[str, Any]],
    out_dir: Path,
    *,
    robots: Sequence[str] | None = None,
    rssi_robot: str = "robot-1",
    thresholds: Mapping[str, float] | None = None,
) -> list[Path]:
    """Write fig4_free_memory.png, fig5_rssi.png and fig6_states.png; their paths.

    `robots`: the panels of Fig. 4 (default: the robots the recorder polled). `thresholds`:
    changes to PAPER_THRESHOLDS (keys allocation_mem_free, shortage_mem_free, rssi).
    """
    from matplotlib.figure import Figure  # noqa: PLC0415 - only the demo needs matplotlib

    unknown = set(thresholds or {}) - set(PAPER_THRESHOLDS)
    if unknown:
        raise ValueError(f"unknown thresholds {sorted(unknown)}; known: {sorted(PAPER_THRESHOLDS)}")
    limits = {**PAPER_THRESHOLDS, **(thresholds or {})}
    tl = Timeline(timeline)
    names = list(robots) if robots is not None else tl.robots()
    end = max([0.0, *(float(line["t"]) for line in tl.lines)])
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []

    fig = Figure(figsize=(8, 1.9 * max(1, len(names)) + 0.6), layout="constrained")
    axes = fig.subplots(max(1, len(names)), 1, sharex=True, squeeze=False)[:, 0]
    for ax, robot in zip(axes, names, strict=False):
        ts, mem = _series(tl, robot, "mem_free", scale=1 / MB)
        ax.plot(ts, mem, color="tab:blue", linewidth=1.2, label="free memory")
        ax.axhline(
            limits["allocation_mem_free"] / MB,
            color="tab:green",
            linestyle=":",
            label=f"allocation threshold ({limits['allocation_mem_free'] / MB:g} MB)",
        )
        ax.axhline(
            limits["shortage_mem_free"] / MB,
            color="tab:red",
            linestyle=":",
            label=f"memory shortage ({limits['shortage_mem_free'] / MB:g} MB)",
        )
        ax.set_ylabel("free memory [MB]")
        ax.set_ylim(bottom=0)
        ax.set_title(f"Free memory of {robot}", fontsize=10)
        _marks(ax, tl)
    _legend(fig, axes[0])
    _time_axis(axes[-1], end)
    paths.append(_save(fig, out_dir / "fig4_free_memory.png"))

    fig = Figure(figsize=(8, 3), layout="constrained")
    ax = fig.subplots()
    ts, rssi = _series(tl, rssi_robot, "rssi")
    ax.plot(ts, rssi, color="tab:blue", linewidth=1.2, label="RSSI")
    ax.axhline(
        limits["rssi"],
        color="tab:red",
        linestyle=":",
        label=f"communication failure ({limits['rssi']:g} dBm)",
    )
    ax.set_ylabel("RSSI [dBm]")
    ax.set_title(f"WiFi status (RSSI) of {rssi_robot}", fontsize=10)
    _marks(ax, tl)
    ax.margins(y=0.15)
    _legend(fig, ax)
    _time_axis(ax, end)
    paths.append(_save(fig, out_dir / "fig5_rssi.png"))

    paths.append(_states_figure(tl, end, out_dir / "fig6_states.png"))
    return paths


def _states_figure(tl: Timeline, end: float, path: Path) -> Path:
    from matplotlib.figure import Figure  # noqa: PLC0415 - same

    rows = _state_rows(tl, end)
    fig = Figure(figsize=(8, 0.45 * max(1, len(rows)) + 1.4), layout="constrained")
    ax = fig.subplots()
    used: set[str] = set()
    for y, (_, segments) in enumerate(rows.values()):
        for style, spans in segments.items():
            kw = dict(STATE_STYLES[style])
            label = kw.pop("label")
            ax.broken_barh(spans, (y - 0.35, 0.7), label=None if style in used else label, **kw)
            used.add(style)
    labels = [
        f"{r}: {i}" + ("" if i.startswith(c) else f" ({c})") for (r, i), (c, _) in rows.items()
    ]
    ax.set_yticks(range(len(rows)), labels, fontsize=8)
    ax.set_ylim(max(1, len(rows)) - 0.5, -0.5)
    if not rows:
        ax.text(0.5, 0.5, "no component states recorded", ha="center", transform=ax.transAxes)
    ax.set_title("RT-Component states", fontsize=10)
    _marks(ax, tl)
    _legend(fig, ax)
    _time_axis(ax, end)
    return _save(fig, path)


def _state_rows(tl: Timeline, end: float) -> Rows:
    """(robot, instance) -> (component, style -> [(start, width)]), rows in order of appearance."""
    current: dict[tuple[str, str], tuple[float, str | None]] = {}
    rows: Rows = {}
    for line in [*tl.of("state"), {"t": end, "kind": "end"}]:
        keys = list(current) if line["kind"] == "end" else [_row_key(line)]
        for key in keys:
            if key in current:
                since, style = current.pop(key)
                if style is not None and line["t"] > since:
                    rows[key][1].setdefault(style, []).append((since, line["t"] - since))
        if line["kind"] == "state":
            key = keys[0]
            rows.setdefault(key, (str(line.get("component") or ""), {}))
            current[key] = (float(line["t"]), _style(line))
    return rows


def _row_key(line: dict[str, Any]) -> tuple[str, str]:
    return str(line.get("robot")), str(line.get("instance"))


def _style(line: dict[str, Any]) -> str | None:
    wire = line.get("state")
    state = state_from_wire(wire) if isinstance(wire, str) else None
    if state == LifecycleState.ACTIVE:
        standby = line.get("role") == InstanceRole.STANDBY
        return InstanceRole.STANDBY if standby else LifecycleState.ACTIVE
    if state in (LifecycleState.INACTIVE, LifecycleState.ERROR):
        return state
    return None if wire in ("gone", None) or state == LifecycleState.FINALIZED else "other"


def _series(
    tl: Timeline, robot: str, field: str, scale: float = 1.0
) -> tuple[list[float], list[float]]:
    """(t, value) of a robot's samples; NaN where a value is missing or across a gap > GAP_S."""
    ts: list[float] = []
    values: list[float] = []
    for line in tl.of("sample", robot=robot):
        t, v = float(line["t"]), line.get(field)
        if ts and t - ts[-1] > GAP_S:
            ts.append(ts[-1])
            values.append(math.nan)
        ts.append(t)
        values.append(v * scale if isinstance(v, int | float) else math.nan)
    return ts, values


def _marks(ax: Axes, tl: Timeline) -> None:
    for what, style in MARK_STYLES.items():
        for n, t in enumerate(tl.marks(what)):
            kw = dict(style)
            if n:
                kw.pop("label")
            ax.axvline(t, linewidth=1.2, **kw)


def _legend(fig: Any, ax: Axes) -> None:
    """One legend below the figure, from the panel that has every label."""
    handles, labels = ax.get_legend_handles_labels()
    if handles:
        fig.legend(handles, labels, loc="outside lower center", ncols=3, fontsize=7)


def _time_axis(ax: Axes, end: float) -> None:
    ax.set_xlim(0.0, max(end, 1.0))
    ax.set_xlabel("time since start [s]")


def _save(fig: Any, path: Path) -> Path:
    fig.savefig(path, dpi=110)
    return path


def summary_table(timeline: list[dict[str, Any]]) -> str:
    """Marks, events and instance state changes in time order, one per line, as text."""
    rows = ["     t [s]  what"]
    for line in Timeline(timeline).lines:
        kind = line.get("kind")
        if kind == "mark":
            text = f"mark {line.get('what')}: {line.get('label', '')}"
        elif kind == "state":
            state, role = line.get("state"), line.get("role")
            text = f"{line.get('robot')}: {_instance(line)} {state}, role {role}"
        elif kind == "event":
            text = f"{line.get('robot')}: {line.get('event')} {_short(line.get('detail'))}"
        elif kind == "agent" and line.get("status") == "down":
            text = f"{line.get('robot')}: agent not answering ({line.get('error', '')})"
        else:
            continue
        rows.append(f"{float(line['t']):10.2f}  {text.rstrip()}")
    return "\n".join(rows) + "\n"


def _instance(line: dict[str, Any]) -> str:
    """'CameraRTC-s1', or 'cam-a (CameraRTC)' when the name does not tell the component."""
    name, component = str(line.get("instance")), str(line.get("component") or "")
    return name if name.startswith(component) else f"{name} ({component})"


def _short(detail: Any, width: int = 70) -> str:
    if not isinstance(detail, dict) or not detail:
        return ""
    text = ", ".join(f"{k}={v}" for k, v in detail.items())
    return text if len(text) <= width else text[: width - 3] + "..."
