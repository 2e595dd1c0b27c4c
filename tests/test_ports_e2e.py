"""End to end on two real agents: the camera and a consumer run on robot-2; the command line talks
only to robot-1, which passes every port request on to robot-2 (peer token). The camera is
recorded to MCAP, the file read with `mcap.reader`, replayed into the consumer, and the consumer's
bytes equal the recording's, in order. Then a counter on robot-1 is connected at run time to
the consumer on robot-2 (robot-1 asks robot-2 what the port is, and sends to the data address
robot-2's record gives), and disconnected."""

from __future__ import annotations

from pathlib import Path

import msgpack
import pytest
from mcap.reader import make_reader

from components.ledger import read_frames
from sdrpeer.cli.main import main as cli_main
from tests.realnet import RealCluster, http

pytestmark = pytest.mark.realnet


def test_a_camera_on_another_robot_is_recorded_and_replayed_through_my_agent(
    cluster: RealCluster, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    one, two = cluster.start_many(2)
    sink_dir = tmp_path / "sink"
    specs = [
        {
            "name": "Cam",
            "target": "components.camera:Camera",
            "params": {"rate": 50.0, "width": 32, "height": 24},
        },
        {
            "name": "Sink",
            "target": "components.ledger:FrameLedger",
            "params": {"dir": str(sink_dir)},
        },
    ]
    status, body = http("POST", two.api + "/v1/instances", {"instances": specs}, two.token)
    assert status == 200, body
    cluster.wait_until(
        lambda: {i["name"]: i["state"] for i in one.member("robot-2")["instances"]},
        lambda states: states == {"Cam": "active", "Sink": "active"},
        "robot-1 hears that Cam and Sink are active on robot-2",
    )
    api = ["--api", one.api, "--token", one.token]

    assert cli_main(["port", "list", *api]) == 0
    rows = [line.split() for line in capsys.readouterr().out.splitlines()[1:]]
    assert ["robot-2", "Cam.image", "out"] in [row[:3] for row in rows]

    out = tmp_path / "cam.mcap"
    assert cli_main(["port", "record", "Cam.image", "-o", str(out), "--count", "15", *api]) == 0
    with out.open("rb") as f:
        reader = make_reader(f)
        messages = [(c, m) for _, c, m in reader.iter_messages(log_time_order=False)]
    assert len(messages) == 15
    assert {c.metadata["robot"] for c, _ in messages} == {"robot-2"}
    recorded = [m.data for _, m in messages]
    seqs = [msgpack.unpackb(d)["seq"] for d in recorded]
    assert seqs == list(range(seqs[0], seqs[0] + 15))

    argv = ["port", "replay", str(out), "--map", "Cam.image=Sink.inp", "--speed", "0", *api]
    assert cli_main(argv) == 0
    kept = cluster.wait_until(
        lambda: read_frames(str(sink_dir)) if sink_dir.exists() else [],
        lambda frames: len(frames) >= 15,
        "the replayed frames at Sink",
    )
    assert kept == recorded

    # robot-2's own token is not needed, robot-1's is: without it nothing is passed on
    status, _ = http("POST", one.api + "/v1/ports/inject", {"port": "Sink.inp", "value": 1}, None)
    assert status == 401

    pub = {"name": "Pub", "target": "tests.components_fixture:Counter", "params": {"rate": 100}}
    status, body = http("POST", one.api + "/v1/instances", {"instances": [pub]}, one.token)
    assert status == 200, body
    cluster.wait_until(
        lambda: {i["name"]: i["state"] for i in one.get("/v1/instances")},
        lambda states: states == {"Pub": "ACTIVE"},
        "Pub ACTIVE on robot-1",
    )
    assert cli_main(["port", "connect", "Pub.out", "Sink.nope", *api]) == 1
    assert "Sink on robot-2 has no port 'nope'" in capsys.readouterr().err
    assert cli_main(["port", "connect", "Pub.out", "Sink.inp", *api]) == 0
    counts = cluster.wait_until(
        lambda: [msgpack.unpackb(d) for d in read_frames(str(sink_dir))[15:]],
        lambda values: len(values) >= 10,
        "Pub's numbers at Sink on robot-2",
    )
    assert all(isinstance(n, int) for n in counts)
    assert counts == sorted(counts)
    [made] = one.get("/v1/instances")[0]["connections"]
    assert made["addr"].startswith("tcp://")
    assert cli_main(["port", "disconnect", "Pub.out", "Sink.inp", *api]) == 0
    cluster.wait_until(
        lambda: one.get("/v1/instances")[0]["connections"], lambda c: c == [], "disconnected"
    )
