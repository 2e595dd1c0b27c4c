"""Planned moves: what the allocator is asked for (pure), and a move on real agents that loses
no frame of a fifo/block stream."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from components.ledger import ledger_system, read_ledgers
from sdrpeer.cli.main import main
from sdrpeer.deploy.move import move_inputs
from sdrpeer.errors import MoveError
from sdrpeer.plan import Placement, Plan
from sdrpeer.system.loader import parse_system
from sdrpeer.vocabulary import InstanceRole
from tests.realnet import RealCluster, http
from tests.test_recovery_e2e import deploy, status


def plan_with(placements: tuple[Placement, ...], *, standby: bool = False) -> Plan:
    system = parse_system(ledger_system("", standby=standby), "moves.yaml")
    return Plan(1, 1, system, placements, "robot-1")


SEQ = Placement("Sequencer", "Sequencer", "robot-1", InstanceRole.ACTIVE, "hot")
LEDGER = Placement("Ledger", "Ledger", "robot-2", InstanceRole.ACTIVE, "hot")
STANDBY = Placement("Ledger", "Ledger-s1", "robot-3", InstanceRole.STANDBY, "hot")
ALIVE = ("robot-1", "robot-2", "robot-3")


def test_a_move_to_a_robot_pins_the_component_there_for_one_allocation() -> None:
    plan = plan_with((SEQ, LEDGER))
    inputs = move_inputs(plan, "Ledger", "robot-3", ALIVE)
    assert inputs.origin == "robot-2"
    assert inputs.avoid == {}
    assert [c.pin for c in inputs.system.components] == ["robot-1", "robot-3"]
    assert plan.system is not None
    assert [c.pin for c in plan.system.components] == ["robot-1", None]  # not remembered


def test_a_move_onto_the_robot_of_a_standby_promotes_it() -> None:
    plan = plan_with((SEQ, LEDGER, STANDBY), standby=True)
    inputs = move_inputs(plan, "Ledger", "robot-3", ALIVE)
    assert inputs.previous.active_of("Ledger") == replace(STANDBY, role=InstanceRole.ACTIVE)


def test_a_move_without_a_destination_avoids_the_current_robot() -> None:
    inputs = move_inputs(plan_with((SEQ, LEDGER)), "Ledger", None, ALIVE)
    assert inputs.avoid == {"Ledger": {"robot-2"}}


@pytest.mark.parametrize(
    ("component", "to", "error"),
    [
        ("Nope", "robot-3", "no component 'Nope'"),
        ("Ledger", "robot-2", "already runs on robot-2"),
        ("Ledger", "robot-9", "robot 'robot-9' is not alive"),
        ("Sequencer", "robot-2", "pinned to robot-1 by the system file"),
    ],
)
def test_moves_that_cannot_be_asked_for_say_why(component: str, to: str, error: str) -> None:
    with pytest.raises(MoveError, match=error):
        move_inputs(plan_with((SEQ, LEDGER)), component, to, ALIVE)
    with pytest.raises(MoveError, match="no system is deployed"):
        move_inputs(None, "Ledger", None, ALIVE)


@pytest.mark.realnet
def test_planned_moves_on_real_agents_lose_no_frame(
    cluster: RealCluster, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    agents = cluster.start_many(3)
    one = agents[0]
    ledger = tmp_path / "ledger"
    path = tmp_path / "system.yaml"
    path.write_text(ledger_system(str(ledger)))
    deploy(cluster, one, path)

    def ledger_on(robot: str) -> bool:
        rows = status(one)["components"]
        return any(
            c["component"] == "Ledger" and c["robot"] == robot and c["state"] == "active"
            for c in rows
        )

    def taken() -> int:
        return int(read_ledgers(str(ledger))["highest"]) if ledger.exists() else 0

    cluster.wait_until(taken, lambda n: n > 50, "the Ledger taking numbers")
    for to in ("robot-3", "robot-2"):
        code, doc = http("POST", one.api + "/v1/move", {"component": "Ledger", "to": to}, one.token)
        assert code == 200, doc
        assert doc["robot"] == to
        cluster.wait_until(lambda to=to: ledger_on(to), bool, f"Ledger ACTIVE on {to}", 30)  # type: ignore[misc]
        mark = taken()
        cluster.wait_until(taken, lambda n, mark=mark: n > mark + 50, "numbers flowing again")  # type: ignore[misc]
    # the CLI does the same, and waits
    where = ["--api", one.api, "--token", one.token]
    assert main(["move", "Ledger", "--to", "robot-3", "--wait", *where]) == 0
    assert "Ledger ACTIVE on robot-3 after" in capsys.readouterr().out
    assert ledger_on("robot-3")
    assert main(["move", "Ledger", "--to", "robot-3", *where]) == 1  # already there
    assert "already runs on robot-3" in capsys.readouterr().err
    mark = taken()
    cluster.wait_until(taken, lambda n: n > mark + 50, "numbers flowing again")
    figures = read_ledgers(str(ledger))
    assert figures["files"] == 4  # one per instance that ran
    assert figures["lost"] == 0
    assert figures["duplicates"] == 0
    moves = [e for a in agents for e in a.events() if e["kind"] == "move"]  # the allocator's
    assert len(moves) == 3
    code, doc = http("POST", one.api + "/v1/move", {"component": "Ledger", "to": "robot-3"}, "")
    assert code == 401  # a state change needs the token
