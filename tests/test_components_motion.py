"""REDController and PositionEstimation: the pure rules by table, then as running components."""

from __future__ import annotations

import math
from typing import Any

import pytest

from components.position_estimation import Area, Estimator, PositionEstimation
from components.red_controller import Odometry, REDController, decide, integrate, wrap_angle
from sdrpeer.sdk import CallbackError, ComponentRunner, LifecycleState
from tests.test_components_vision import ListSink
from tests.wait import until_async


@pytest.mark.parametrize(
    ("alarm", "inside", "v", "w", "reason"),
    [
        (False, True, 0.2, 0.3, None),
        (True, True, 0.0, 0.0, "alarm"),
        (False, False, 0.0, 0.0, "outside"),
        (True, False, 0.0, 0.0, "alarm,outside"),
    ],
)
def test_decide(alarm: bool, inside: bool, v: float, w: float, reason: str | None) -> None:
    cmd = decide(alarm, inside, 0.2, 0.3)
    assert (cmd.v, cmd.w, cmd.reason, cmd.stopped) == (v, w, reason, reason is not None)


@pytest.mark.parametrize(
    ("v", "w", "dt", "drift", "expected"),
    [
        (1.0, 0.0, 2.0, 0.0, (2.0, 0.0, 0.0)),
        (0.0, 0.5, 2.0, 0.0, (0.0, 0.0, 1.0)),
        (0.0, 0.0, 5.0, 0.0, (0.0, 0.0, 0.0)),
        (1.0, 0.0, 1.0, 0.1, (math.cos(0.05), math.sin(0.05), 0.1)),
        (-1.0, 0.0, 1.0, 0.0, (-1.0, 0.0, 0.0)),
    ],
)
def test_integrate(
    v: float, w: float, dt: float, drift: float, expected: tuple[float, float, float]
) -> None:
    odo = integrate(Odometry(), v, w, dt, drift)
    assert (odo.x, odo.y, odo.theta) == pytest.approx(expected)


def test_integrating_a_full_circle_comes_back_to_the_start() -> None:
    odo = Odometry()
    for _ in range(628):  # 2*pi s at 1 rad/s
        odo = integrate(odo, 0.5, 1.0, 0.01)
    assert (odo.x, odo.y) == pytest.approx((0.0, 0.0), abs=0.01)
    assert wrap_angle(odo.theta) == pytest.approx(wrap_angle(6.28), abs=1e-9)


@pytest.mark.parametrize(
    ("text", "area"),
    [("-1,-1,1,1", Area(-1, -1, 1, 1)), ("[0, 0, 2.5, 3]", Area(0, 0, 2.5, 3))],
)
def test_area_parse(text: str, area: Area) -> None:
    assert Area.parse(text) == area


@pytest.mark.parametrize(
    ("text", "message"),
    [("1,2,3", "four numbers"), ("a,b,c,d", "four numbers"), ("1,1,0,2", "xmin < xmax")],
)
def test_area_parse_errors(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Area.parse(text)


def test_estimator_removes_the_heading_bias_of_the_odometry() -> None:
    truth = odo = Odometry()
    est = Estimator(bias=0.05)
    est.update(odo)
    for _ in range(300):  # 30 s of driving an arc at 10 Hz
        truth = integrate(truth, 0.2, 0.1, 0.1)
        odo = integrate(odo, 0.2, 0.1, 0.1, drift=0.05)
        pose = est.update(odo)
    raw_error = math.hypot(odo.x - truth.x, odo.y - truth.y)
    est_error = math.hypot(pose.x - truth.x, pose.y - truth.y)
    assert raw_error > 0.3
    assert est_error < 0.01
    assert pose.theta == pytest.approx(truth.theta, abs=1e-6)


def test_estimator_skips_a_glitch_and_handles_reversing() -> None:
    est = Estimator(max_step=0.5)
    est.update(Odometry(0.0, 0.0, 0.0))
    assert est.update(Odometry(0.1, 0.0, 0.0)).x == pytest.approx(0.1)
    assert est.update(Odometry(5.0, 0.0, 0.0)).x == pytest.approx(0.1)  # a jump: ignored
    assert est.glitches == 1
    assert est.update(Odometry(5.2, 0.0, 0.0)).x == pytest.approx(0.3)  # re-anchored
    assert est.update(Odometry(5.0, 0.0, 0.0)).x == pytest.approx(0.1)  # backwards


async def start(component: Any, *outs: str) -> tuple[ComponentRunner, dict[str, ListSink]]:
    """A running (ACTIVE) runner with a ListSink on each named OutPort."""
    sinks = {name: ListSink() for name in outs}
    for name, sink in sinks.items():
        component.outport(name).attach(sink)
    runner = ComponentRunner(component)
    await runner.initialize()
    await runner.activate()
    return runner, sinks


async def test_controller_drives_stops_on_alarm_and_outside_and_integrates() -> None:
    ctl = REDController(params={"rate": 200.0, "speed": 0.5, "turn": 0.0, "drift": 0.0})
    runner, sinks = await start(ctl, "cmd", "odometry")
    cmd, odo = sinks["cmd"].values, sinks["odometry"].values
    await until_async("len(cmd) >= 10", lambda: len(cmd), lambda v: v >= 10)
    assert cmd[0]["stopped"] is False
    assert (cmd[0]["v"], cmd[0]["w"], cmd[0]["reason"]) == (0.5, 0.0, None)
    await until_async("odo[-1]['x'] > 0.02", lambda: odo[-1]["x"], lambda v: v > 0.02)
    assert odo[-1]["y"] == 0.0
    ctl.alarm.deliver({"alarm": True, "ts": 0.0, "where": [1, 2], "source": 7}, 1, "det")
    await until_async(
        "cmd[-1]['reason'] == 'alarm'", lambda: cmd[-1]["reason"], lambda v: v == "alarm"
    )
    assert (cmd[-1]["v"], cmd[-1]["w"], cmd[-1]["stopped"]) == (0.0, 0.0, True)
    n = len(odo)
    await until_async("len(odo) > n + 5", lambda: len(odo), lambda v: v > n + 5)
    assert odo[-1]["x"] == odo[-4]["x"]  # standing still
    ctl.alarm.deliver({"alarm": False, "ts": 0.0, "where": None, "source": 8}, 2, "det")
    ctl.pose.deliver({"x": 3.0, "y": 0.0, "theta": 0.0, "inside": False, "ts": 0.0}, 1, "pe")
    await until_async(
        "cmd[-1]['reason'] == 'outside'", lambda: cmd[-1]["reason"], lambda v: v == "outside"
    )
    ctl.pose.deliver({"x": 0.0, "y": 0.0, "theta": 0.0, "inside": True, "ts": 0.0}, 2, "pe")
    await until_async("not cmd[-1]['stopped']", lambda: not cmd[-1]["stopped"])
    assert ctl.stops == 1  # alarm, then outside without driving in between: one stop
    assert [c["reason"] for c in cmd if c["stopped"]][-1] == "outside"
    # Odometry is the integral of the commands: x grows by v * elapsed while driving.
    xs = [o["x"] for o in odo]
    assert xs == sorted(xs)
    ts = [o["ts"] for o in odo]
    step = 5.0 / 200.0  # the controller integrates at most 5 periods at once (a stalled loop)
    moving = sum(
        min(b - a, step) for a, b, c in zip(ts, ts[1:], cmd[: len(ts) - 1], strict=False) if c["v"]
    )
    assert xs[-1] == pytest.approx(0.5 * moving, rel=0.25)
    await runner.finalize()


async def test_position_estimation_flags_leaving_the_area() -> None:
    pe = PositionEstimation(params={"area": "-1,-1,1,1", "bias": 0.0})
    runner, sinks = await start(pe, "pose")
    poses = sinks["pose"].values
    for seq, x in enumerate((0.0, 0.4, 0.8, 1.2, 0.9), start=1):
        pe.odometry.deliver({"x": x, "y": 0.0, "theta": 0.0, "ts": 0.0}, seq, "ctl")
        await until_async(
            f"pose {seq}",
            lambda: len(poses),
            lambda v, n=seq: v == n,  # type: ignore[misc]
        )
    assert [p["inside"] for p in poses] == [True, True, True, False, True]
    assert [p["x"] for p in poses] == pytest.approx([0.0, 0.4, 0.8, 1.2, 0.9])
    assert set(poses[0]) == {"x", "y", "theta", "inside", "ts"}
    await runner.set_params({"area": "-2,-2,2,2"})
    pe.odometry.deliver({"x": 1.3, "y": 0.0, "theta": 0.0, "ts": 0.0}, 6, "ctl")
    await until_async("len(poses) == 6", lambda: len(poses), lambda v: v == 6)
    assert poses[-1]["inside"] is True
    await runner.finalize()


async def test_position_estimation_with_a_bad_area_goes_to_error_saying_why() -> None:
    runner = ComponentRunner(PositionEstimation(params={"area": "1,2,3"}))
    with pytest.raises(CallbackError, match="four numbers"):
        await runner.initialize()
    assert runner.state is LifecycleState.ERROR
