"""docs/protocol.md's deadlines table stays true: it is what `sdrpeer.agent.deadlines` renders
from the presets, every preset has its column, and the rows read the presets' own fields."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import pytest

from sdrpeer.agent import deadlines
from sdrpeer.agent.tuning import PRESETS, preset

DOC = Path(__file__).resolve().parent.parent / "docs" / "protocol.md"
TABLE = re.compile(
    r"<!-- deadlines table:.*?-->\n(?P<table>.*?)<!-- end of the deadlines table -->", re.DOTALL
)


def test_the_doc_holds_the_table_the_presets_give() -> None:
    found = TABLE.search(DOC.read_text())
    assert found is not None, "docs/protocol.md lost its deadlines table markers"
    assert found["table"] == deadlines.markdown(), (
        "docs/protocol.md's deadlines table differs from the presets: paste the output of "
        "`python -m sdrpeer.agent.deadlines` between its markers"
    )


def test_every_preset_has_a_column() -> None:
    head = deadlines.markdown().splitlines()[0]
    assert [f"`{name}`" in head for name in PRESETS] == [True] * len(PRESETS)


@pytest.mark.parametrize(
    ("row", "part", "field"),
    [
        ("gossip.probe_timeout", "gossip", "probe_timeout"),
        ("election.grace", "election", "grace"),
        ("supervisor.hello_timeout", "supervisor", "hello_timeout"),
        ("supervisor.heartbeat_timeout", "supervisor", "heartbeat_timeout"),
    ],
)
def test_a_row_follows_its_preset_field(row: str, part: str, field: str) -> None:
    """A preset field changed is the row's value changed (the table reads the dataclass)."""
    (deadline,) = [d for d in deadlines.DEADLINES if d.setting == row]
    tuning = preset("lan")
    changed = tuning.with_(**{part: replace(getattr(tuning, part), **{field: 12.5})})
    assert deadline.seconds(changed) == 12.5
    assert deadline.seconds(tuning) == getattr(getattr(tuning, part), field)


def test_the_suspicion_rows_are_the_gossip_formula() -> None:
    lab = preset("lab").gossip
    rows = {d.setting: d.seconds(preset("lab")) for d in deadlines.DEADLINES}
    assert rows["suspicion, 10 robots or fewer"] == pytest.approx(6.5 * 0.3)
    assert rows["suspicion at most, 10 robots or fewer"] == pytest.approx(
        lab.suspicion_mult * lab.probe_interval * lab.suspicion_max_mult
    )
