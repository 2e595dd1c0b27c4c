"""A fast producer into a slow consumer on real agents: with the InPort's default policy (all, 8,
overwrite) the frames its full buffer throws away are counted at the sender, warned about as a
`port.overflow` event, and shown on the connection in `sdrpeer status`; with `full: block` on
the connection (a system file's `policy:`), the receiving InPort keeps every frame instead."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.realnet import Agent, RealCluster
from tests.test_recovery_e2e import deploy, status

pytestmark = pytest.mark.realnet

SYSTEM = """\
name: {name}
components:
  - name: Pub
    target: tests.components_fixture:Counter
    params: {{rate: 400}}
  - name: Lag
    target: tests.components_fixture:Laggard
    params: {{rate: 20}}
connections:
  - {{from: Pub.out, to: Lag.inp{policy}}}
"""


def write(tmp_path: Path, name: str, policy: str = "") -> Path:
    path = tmp_path / f"{name}.yaml"
    path.write_text(SYSTEM.format(name=name, policy=policy))
    return path


def ports(agent: Agent, component: str) -> dict[str, dict[str, int]]:
    rows = [r for r in agent.get("/v1/instances") if r.get("component") == component]
    return dict(rows[0]["ports"]) if rows else {}


def overflow_events(agent: Agent) -> list[dict[str, Any]]:
    return [e for e in agent.events() if e["kind"] == "port.overflow"]


def test_frames_lost_to_a_full_inport_are_counted_warned_and_shown(
    cluster: RealCluster, tmp_path: Path
) -> None:
    agent = cluster.start("robot-1")
    deploy(cluster, agent, write(tmp_path, "lossy"))
    events = cluster.wait_until(lambda: overflow_events(agent), bool, "a port.overflow event")
    assert (events[0]["detail"]["component"], events[0]["detail"]["port"]) == ("Pub", "out")
    assert events[0]["detail"]["frames"] > 0
    sent = cluster.wait_until(
        lambda: ports(agent, "Pub").get("out", {}),
        lambda c: c.get("dropped_remote", 0) > 0,
        "drops",
    )
    assert sent["overflowed"] >= sent["dropped_remote"]  # the InPort's, told back by its acks
    cluster.wait_until(  # and the receiving side counts them too (from Lag's heartbeats)
        lambda: ports(agent, "Lag").get("inp", {}), lambda c: c.get("dropped", 0) > 0, "Lag drops"
    )
    row = cluster.wait_until(
        lambda: status(agent)["connections"][0], lambda c: (c["lost_per_s"] or 0) > 0, "lost/s"
    )
    assert (row["from"], row["to"]) == ("Pub.out", "Lag.inp")
    from sdrpeer.cli.status import format_status  # noqa: PLC0415 - the CLI's table

    assert "LOST" in format_status(status(agent))


def test_a_connections_block_policy_keeps_every_frame_at_the_receiver(
    cluster: RealCluster, tmp_path: Path
) -> None:
    agent = cluster.start("robot-1")
    deploy(cluster, agent, write(tmp_path, "kept", ", policy: {full: block, buffer: 100000}"))
    cluster.wait_until(  # the consumer is behind: frames wait at its InPort
        lambda: ports(agent, "Lag").get("inp", {}),
        lambda c: c.get("frames_in", 0) > 200,
        "200 frames in",
    )
    got, sent = ports(agent, "Lag")["inp"], ports(agent, "Pub")["out"]
    assert got["dropped"] == 0  # the class's overwrite 8 did not apply: the connection's did
    assert (sent["overflowed"], sent["dropped_remote"]) == (0, 0)
    assert overflow_events(agent) == []
    (lag,) = [r for r in agent.get("/v1/instances") if r["component"] == "Lag"]
    assert lag["data_plane"]["accepted"] >= 1  # its data server's counters, from heartbeats
