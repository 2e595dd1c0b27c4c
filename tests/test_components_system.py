"""The five demonstration components wired as one robot: in-process, then as five real hosts."""

from __future__ import annotations

from typing import Any

import psutil

from components.anomaly_detection import AnomalyDetection
from components.camera import Camera, OmnidirectionalCamera
from components.position_estimation import PositionEstimation
from components.red_controller import REDController
from sdrpeer.sdk import Component, ComponentRunner, InPortRuntime
from tests.hostctl import HostPool, HostProc
from tests.test_components_vision import ListSink
from tests.wait import until, until_async

MIB = 1024 * 1024
FAST = {"rate": "20", "hazard_period": "1.0", "hazard_on": "0.4"}
"""Camera params for tests: the dangerous object shows up 40 % of each second."""
DRIVE = {"rate": "20", "speed": "0.5", "turn": "0.5"}
AREA = {"area": "-0.3,-0.3,0.3,0.3"}
"""A small area: the robot leaves it after about a second of driving."""
WIRING = [
    ("OmniCam", "image", "Detector", "image"),
    ("Cam", "image", "Detector", "image"),
    ("Detector", "alarm", "Controller", "alarm"),
    ("Controller", "odometry", "Estimator", "odometry"),
    ("Estimator", "pose", "Controller", "pose"),
]
"""(from instance, OutPort, to instance, InPort): the paper's robot system."""


class Wire:
    """An OutPort sink that delivers straight into another component's InPort."""

    def __init__(self, port: InPortRuntime, conn: str) -> None:
        self.port = port
        self.conn = conn
        self.seq = 0

    def offer(self, value: Any) -> bool:
        self.seq += 1
        self.port.deliver(value, self.seq, self.conn)
        return True


async def test_reserve_mb_is_allocated_touched_and_freed() -> None:
    me = psutil.Process()
    cam = Camera(params={"reserve_mb": 200, "rate": 1.0})
    runner = ComponentRunner(cam)
    await runner.initialize()
    before = me.memory_info().rss
    await runner.activate()
    held = me.memory_info().rss
    assert cam.reserve.size == 200 * MIB
    await runner.deactivate()
    after = me.memory_info().rss
    await runner.finalize()
    assert held - before > 180 * MIB  # touched, so resident
    assert held - after > 180 * MIB  # and given back
    assert cam.reserve.size == 0


async def test_five_components_in_process_alarm_stop_and_leave_the_area() -> None:
    parts: dict[str, Component] = {
        "OmniCam": OmnidirectionalCamera(params={**FAST, "seed": 3}),
        "Cam": Camera(params={**FAST, "seed": 4}),
        "Detector": AnomalyDetection(),
        "Controller": REDController(params=DRIVE),
        "Estimator": PositionEstimation(params=AREA),
    }
    for src, out, dst, inp in WIRING:
        parts[src].outport(out).attach(Wire(parts[dst].inport(inp), f"{src}.{out}"))
    alarms, cmds, poses = ListSink(), ListSink(), ListSink()
    parts["Detector"].outport("alarm").attach(alarms)
    parts["Controller"].outport("cmd").attach(cmds)
    parts["Estimator"].outport("pose").attach(poses)
    runners = [ComponentRunner(c) for c in parts.values()]
    for r in runners:
        await r.initialize()
    for r in reversed(runners):  # consumers first, as an agent would
        await r.activate()
    try:
        await until_async(
            "any(not p['inside'] for p in poses.values)",
            lambda: any(not p["inside"] for p in poses.values),
            within=10.0,
        )
        await until_async(
            "any('outside' in (c['reason'] or '') for c in cmds.values)",
            lambda: any("outside" in (c["reason"] or "") for c in cmds.values),
            within=10.0,
        )
    finally:
        for r in runners:
            await r.finalize()
    raised = [a for a in alarms.values if a["alarm"]]
    assert raised
    assert all(a["where"] is not None for a in raised)
    assert any(not a["alarm"] for a in alarms.values)
    assert any(c["reason"] == "alarm" for c in cmds.values)
    assert any(not c["stopped"] and c["v"] == 0.5 for c in cmds.values)
    assert cmds.values[-1]["stopped"] is True
    assert poses.values[0]["inside"] is True
    assert len(poses.values) > 10


def params(values: dict[str, str]) -> list[str]:
    """`--param k=v` arguments."""
    return [a for k, v in values.items() for a in ("--param", f"{k}={v}")]


def counted(host: HostProc, port: str, key: str, more_than: int) -> dict[str, int]:
    """Heartbeats until `port`'s counter `key` exceeds `more_than` (bounded: 5 s)."""
    seen: dict[str, int] = {}
    for _ in range(10):
        seen = host.wait_t("heartbeat", 2.0)["ports"][port]
        if seen[key] > more_than:
            return seen
    raise AssertionError(f"{port}.{key} stuck at {seen} (wanted > {more_than})")


def test_five_real_hosts_over_the_data_plane(hosts: HostPool) -> None:
    specs = {
        "OmniCam": ("components.camera:OmnidirectionalCamera", {**FAST, "seed": "3"}),
        "Cam": ("components.camera:Camera", {**FAST, "seed": "4"}),
        "Detector": ("components.anomaly_detection:AnomalyDetection", {}),
        "Controller": ("components.red_controller:REDController", DRIVE),
        "Estimator": ("components.position_estimation:PositionEstimation", AREA),
    }
    procs: dict[str, HostProc] = {}
    hellos: dict[str, dict[str, Any]] = {}
    for name, (target, values) in specs.items():
        procs[name], hellos[name] = hosts.ready(target, *params(values), name=name)
    for i, (src, out, dst, inp) in enumerate(WIRING):
        to = f"unix://{hellos[dst]['data']['unix']}"
        conn = {"id": f"c{i}", "out": out, "to": to, "in": inp, "policy": {"push": "new"}}
        assert procs[src].command("connect", conn=conn)["ok"] is True
    for name in reversed(specs):
        assert procs[name].command("activate")["ok"] is True
    until(
        "the Estimator to see the robot leave the area",
        procs["Estimator"].log_text,
        lambda log: "left the area" in log,
        within=15.0,
        poll=0.1,
    )
    until(
        "the Controller to stop outside",
        procs["Controller"].log_text,
        lambda log: "stop: outside" in log,
        within=15.0,
        poll=0.1,
    )
    assert counted(procs["Detector"], "image", "frames_in", 10)["lost"] == 0
    counted(procs["Detector"], "alarm", "frames_out", 10)
    counted(procs["Controller"], "alarm", "frames_in", 10)
    counted(procs["Controller"], "pose", "frames_in", 10)
    counted(procs["Estimator"], "odometry", "frames_in", 10)
    assert "alarm raised" in procs["Detector"].log_text()
    assert "stop: alarm" in procs["Controller"].log_text()
    for name in specs:
        assert procs[name].command("exit")["ok"] is True
    for proc in procs.values():
        assert proc.wait_exit() == 0
