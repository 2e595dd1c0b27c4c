"""`sdrpeer status` text: the COMPLIANCE column and the table of constraints past their bound."""

from __future__ import annotations

from typing import Any

from sdrpeer.cli.status import format_status


def status(*rows: dict[str, Any]) -> dict[str, Any]:
    comps = [
        {"component": c, "robot": r, "state": "ACTIVE", "since": 0.0, "standbys": []}
        for c, r in (("Ctrl", "robot-1"), ("Motor", "robot-2"), ("Log", "robot-3"))
    ]
    return {
        "allocator": {"name": "robot-1", "epoch": 2},
        "plan": {"epoch": 2, "version": 5, "allocator": "robot-1", "system": "s"},
        "components": comps,
        "connections": [],
        "compliance": list(rows),
    }


def row(component: str, constraint: str, state: str, value: float, bound: float) -> dict[str, Any]:
    return {
        "component": component,
        "constraint": constraint,
        "subject": "Ctrl.cmd->Motor.cmd" if constraint in ("loss", "delay") else "robot-1",
        "robots": ["robot-1", "robot-2"],
        "value": value,
        "bound": bound,
        "must_be": "above" if constraint == "battery" else "below",
        "state": state,
        "since": 3600.0,
    }


def cells(text: str, name: str) -> list[str]:
    line = next(ln for ln in text.splitlines() if ln.startswith(name + " "))
    return line.split()


def test_each_component_says_ok_violated_or_holding() -> None:
    text = format_status(
        status(
            row("Ctrl", "battery", "ok", 70.0, 40.0),
            row("Motor", "loss", "violated", 0.3, 0.05),
            row("Motor", "delay", "holding", 30.0, 20.0),
        ),
        local=False,
    )
    header = text.splitlines()[2].split()
    assert header[-1] == "COMPLIANCE"
    assert cells(text, "Ctrl")[-1] == "ok"
    assert cells(text, "Motor")[-2:] == ["violated:", "loss"]
    assert cells(text, "Log")[-1] == "-"  # no constraint applies to it
    # the constraints past their bound, with value, bound and since when
    table = text.split("COMPONENT  CONSTRAINT")[1].splitlines()
    motor = ["Motor", "loss", "Ctrl.cmd->Motor.cmd", "30.0%", "below", "5.0%", "violated"]
    assert table[1].split() == [*motor, "01:00:00"]
    assert table[2].split()[:2] == ["Motor", "delay"]
    assert table[2].split()[-2:] == ["holding", "01:00:00"]


def test_no_table_when_everything_holds_and_no_column_without_constraints() -> None:
    text = format_status(status(row("Ctrl", "battery", "ok", 70.0, 40.0)), local=False)
    assert "CONSTRAINT" not in text
    assert "COMPLIANCE" in text
    assert "COMPLIANCE" not in format_status(status(), local=False)
