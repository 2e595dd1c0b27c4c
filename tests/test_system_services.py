"""Service bindings in system files: a connection from a consumer's port to a provider's port,
checked against the classes with file:line errors."""

from __future__ import annotations

from pathlib import Path

import pytest

from sdrpeer.errors import SystemFileError
from sdrpeer.system.loader import load_system, parse_system

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "services" / "planning.yaml"

HEAD = (
    "name: s\n"  # 1
    "components:\n"  # 2
    "  - {name: Planner, target: components.planner:PathPlanner}\n"  # 3
    "  - {name: Caller, target: components.planner:PlanCaller}\n"  # 4
    "  - {name: Echo, target: tests.components_fixture:EchoService}\n"  # 5
    "  - {name: Rec, target: tests.components_fixture:Recorder}\n"  # 6
    "  - {name: Caller2, target: components.planner:PlanCaller}\n"  # 7
    "connections:\n"  # 8
)
"""Lines 1-8; the first connection is on line 9."""
BIND = "  - {from: Caller.planner, to: Planner.planner}\n"


def test_a_binding_loads_as_a_connection(tmp_path: Path) -> None:
    text = HEAD + BIND + "  - {from: Caller2.planner, to: Planner.planner}\n"
    system = parse_system(text, "sys.yaml", base_dir=tmp_path)
    conn = system.connections[0]
    assert (conn.from_component, conn.from_port, conn.to_component, conn.to_port) == (
        "Caller",
        "planner",
        "Planner",
        "planner",
    )
    assert conn.id == "Caller.planner->Planner.planner"
    assert conn.traffic_bytes_per_s is None
    assert len(system.connections) == 2  # one provider, two consumers


@pytest.mark.parametrize(
    ("connections", "expected"),
    [
        (
            "  - {from: Planner.planner, to: Caller.planner}\n",
            [
                "sys.yaml:9: field 'connections[0].from': Planner.planner provides a service: a "
                "binding goes from: the consumer (ServiceConsumer) to: the provider",
                "sys.yaml:9: field 'connections[0].to': Caller.planner requires a service",
            ],
        ),
        (
            "  - {from: Caller.planner, to: Echo.svc}\n",
            ["sys.yaml:9: field 'connections[0]': Caller.planner requires demo/Planner#"],
        ),
        (
            "  - {from: Caller.planner, to: Planner.nothing}\n",
            ["sys.yaml:9: field 'connections[0].to': PathPlanner has no port 'nothing'"],
        ),
        (
            "  - {from: Caller.planner, to: Rec.inp}\n",
            ["sys.yaml:9: field 'connections[0]': Caller.planner is a service port but Rec.inp"],
        ),
        (
            "  - {from: Caller.path, to: Planner.planner}\n",
            ["sys.yaml:9: field 'connections[0]': Planner.planner is a service port but "],
        ),
        (
            BIND + "  - {from: Caller.planner, to: Planner.planner}\n",
            ["sys.yaml:10: field 'connections[1]': Caller.planner is bound already (line 9)"],
        ),
        (
            BIND + "  - {from: Caller.planner, to: Echo.svc}\n",
            [
                "sys.yaml:10: field 'connections[1]': Caller.planner is bound already (line 9)",
                "sys.yaml:10: field 'connections[1]': Caller.planner requires demo/Planner#",
            ],
        ),
        (
            "  - {from: Caller.planner, to: Planner.planner, policy: {push: fifo}}\n",
            ["sys.yaml:9: field 'connections[0].policy': a service binding sets only encrypt"],
        ),
    ],
)
def test_a_bad_binding_is_refused_with_its_line(
    tmp_path: Path, connections: str, expected: list[str]
) -> None:
    with pytest.raises(SystemFileError) as info:
        parse_system(HEAD + connections, "sys.yaml", base_dir=tmp_path)
    for line in expected:
        assert line in str(info.value)


def test_an_encrypt_policy_is_allowed(tmp_path: Path) -> None:
    text = HEAD + "  - {from: Caller.planner, to: Planner.planner, policy: {encrypt: false}}\n"
    conn = parse_system(text, "sys.yaml", base_dir=tmp_path).connections[0]
    assert conn.policy == (("encrypt", False),)


def test_the_example_system_binds_the_planner_pair() -> None:
    system = load_system(EXAMPLE)
    (conn,) = system.connections
    assert conn.id == "Caller.planner->Planner.planner"
    assert system.component("Planner").params_map() == {"step": 0.25}
