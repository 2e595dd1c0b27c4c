"""What an eavesdropper captures (a raw socket on loopback, root): gossip between keyed agents
carries no robot name, no component name and no metric in clear; between insecure agents it
does (the same capture finds them: the search can fail)."""

from __future__ import annotations

from pathlib import Path

import msgpack
import pytest

from tests.capture import ROOT_ONLY, Capture
from tests.realnet import Agent, RealCluster, http

pytestmark = [pytest.mark.realnet, ROOT_ONLY]

X_CM, Y_CM = 123_450, 67_890
"""robot-1's position (1234.5 m, 678.9 m) as records and vitals carry it (centimetres)."""

SYSTEM = """name: secret
components:
  - name: SecretSurveyCam
    target: components.camera:Camera
    params: {reserve_mb: 0, rate: 2, width: 32, height: 24}
"""


def plaintext(seen: bytes) -> list[str]:
    """What of the fleet's own words the captured bytes show in clear."""
    found = [
        word
        for word in ("robot-1", "robot-2", "SecretSurveyCam", "components.camera")
        if word.encode() in seen
    ]
    found += [f"position {v}" for v in (X_CM, Y_CM) if msgpack.packb(v) in seen]
    return found


def capture_gossip(cluster: RealCluster, insecure: bool) -> tuple[Capture, list[Agent]]:
    """Two agents gossiping for a while, robot-1 at its distinctive position, captured."""
    first = cluster.start("robot-1", insecure=insecure)
    with Capture([first.gossip_addr[1]]) as capture:
        second = cluster.start("robot-2", join=[first], insecure=insecure)
        capture.ports.add(second.gossip_addr[1])
        cluster.wait_states(first, {"robot-1": "alive", "robot-2": "alive"}, what="two robots")
        code, _ = http("POST", first.api + "/v1/robot", {"pos": [1234.5, 678.9]}, first.token)
        assert code == 200
        cluster.wait_until(
            lambda: (second.members()["robot-1"]["metrics"] or {}).get("pos"),
            lambda pos: pos == [1234.5, 678.9],
            "robot-1's position at robot-2",
        )
        if not insecure:  # insecure robots cannot deploy across robots: no component then
            path = cluster.root / "secret.yaml"
            path.write_text(SYSTEM)
            from tests.test_recovery_e2e import deploy  # noqa: PLC0415 - heavy helpers

            deploy(cluster, first, path)
            cluster.wait_until(
                lambda: (
                    [i["component"] for i in second.members()["robot-1"]["instances"]]
                    + [i["component"] for i in second.members()["robot-2"]["instances"]]
                ),
                lambda comps: "SecretSurveyCam" in comps,
                "the component in gossip",
            )
        captured = len(capture.payloads)  # then more vitals and probes on the wire
        cluster.wait_until(
            lambda: len(capture.payloads), lambda n: n >= captured + 40, "40 more datagrams"
        )
    return capture, [first, second]


def test_keyed_gossip_shows_no_name_metric_or_component(cluster: RealCluster) -> None:
    capture, _ = capture_gossip(cluster, insecure=False)
    assert len(capture.payloads) > 50, "the capture saw the gossip"
    assert plaintext(capture.joined()) == []


def test_insecure_gossip_shows_them_to_the_same_capture(tmp_path: Path) -> None:
    cluster = RealCluster(tmp_path / "insecure")
    try:
        capture, _ = capture_gossip(cluster, insecure=True)
    finally:
        cluster.close()
    seen = plaintext(capture.joined())
    assert "robot-1" in seen
    assert "robot-2" in seen
    assert f"position {X_CM}" in seen
