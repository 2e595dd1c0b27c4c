"""Tables I and II one constraint at a time (pass, fail, no threshold, unknown metric); registry."""

from __future__ import annotations

import pytest

from sdrpeer.alloc.constraints import (
    BUILTIN,
    CONSTRAINTS,
    BatteryAbove,
    CpuBelow,
    DelayBelow,
    DistanceBelow,
    JitterBelow,
    LinkConstraint,
    LossBelow,
    MemFreeAbove,
    Need,
    RobotConstraint,
    RobotLoad,
    RssiAbove,
    active_constraints,
)
from sdrpeer.alloc.strategies import STRATEGIES, FirstFit, Objective
from sdrpeer.alloc.view import RobotView
from sdrpeer.errors import ConfigError
from sdrpeer.plugins.registry import Registry
from sdrpeer.record.robot import LinkStats, Metrics
from sdrpeer.system.model import ComponentDef, Thresholds

MB = 1000**2
COMP = ComponentDef("Cam", "python", "m:C")


def robot(
    name: str = "r1",
    *,
    cpu: float = 10.0,
    free: int = 2000 * MB,
    battery: float | None = 80.0,
    rssi: float | None = -45.0,
    pos: tuple[float, float] | None = (0.0, 0.0),
) -> RobotView:
    return RobotView(name, Metrics(cpu, 4000 * MB, free, battery, rssi, pos))


def check_robot(c: RobotConstraint, r: RobotView, t: Thresholds, **kw: float) -> str | None:
    load = RobotLoad(r, kw.get("cpu_added", 0.0), int(kw.get("mem_added", 0)))
    need = Need(kw.get("cpu", 0.0), int(kw.get("mem", 0)))
    return c.check(load, need, COMP, t)


# -- Table I --------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("robot_cpu", "added", "need", "limit", "ok"),
    [
        (10.0, 0.0, 20.0, 80.0, True),
        (50.0, 20.0, 9.9, 80.0, True),
        (50.0, 20.0, 10.0, 80.0, False),  # exactly at the threshold is not below it
        (70.0, 0.0, 15.0, 80.0, False),
        (95.0, 50.0, 50.0, None, True),  # no threshold: not checked
    ],
)
def test_cpu_below(robot_cpu: float, added: float, need: float, limit: float | None, ok: bool):
    t = Thresholds(cpu_below_pct=limit)
    c = CpuBelow()
    assert c.enabled(t) is (limit is not None)
    why = check_robot(c, robot(cpu=robot_cpu), t, cpu_added=added, cpu=need)
    assert (why is None) is ok
    if not ok:
        assert why is not None
        assert "cpu" in why
        assert "80%" in why


@pytest.mark.parametrize(
    ("free", "added", "need", "ok"),
    [
        (2000, 0, 500, True),
        (1600, 500, 500, True),  # 600MB left
        (1500, 500, 500, False),  # exactly 500MB left: Table V says "500MB or less" fails
        (1000, 0, 520, False),
    ],
)
def test_mem_free_above_counts_what_the_plan_added(free: int, added: int, need: int, ok: bool):
    t = Thresholds(mem_free_above_bytes=500 * MB)
    why = check_robot(MemFreeAbove(), robot(free=free * MB), t, mem_added=added * MB, mem=need * MB)
    assert (why is None) is ok


def test_mem_free_reason_names_after_need_and_limit():
    t = Thresholds(mem_free_above_bytes=500 * MB)
    why = check_robot(MemFreeAbove(), robot(free=900 * MB), t, mem=520 * MB)
    assert why == "free memory 380MB after adding 520MB would not be above 500MB"


def test_memory_without_a_threshold_still_needs_room():
    assert MemFreeAbove().enabled(Thresholds())
    r = robot(free=3000 * MB)
    assert check_robot(MemFreeAbove(), r, Thresholds(), mem_added=1000 * MB, mem=2000 * MB) is None
    why = check_robot(MemFreeAbove(), r, Thresholds(), mem_added=1000 * MB, mem=64_000 * MB)
    assert why == "needs 64GB, only 2GB free"


@pytest.mark.parametrize(
    ("level", "limit", "ok"),
    [
        (80.0, 20.0, True),
        (20.0, 20.0, False),
        (12.0, 20.0, False),
        (None, 20.0, True),
        (5, None, True),
    ],
)
def test_battery_above(level: float | None, limit: float | None, ok: bool):
    t = Thresholds(battery_above_pct=limit)
    why = check_robot(BatteryAbove(), robot(battery=level), t)
    assert (why is None) is ok
    if level == 12.0:
        assert why == "battery 12% not above 20%"


def test_kinds_and_cold_exemptions():
    assert BatteryAbove.static
    assert not CpuBelow.static
    assert not MemFreeAbove.static
    assert not CpuBelow.cold
    assert not MemFreeAbove.cold
    assert BatteryAbove.cold


# -- Table II -------------------------------------------------------------------------------

LINK = LinkStats(rtt_ms=12.0, jitter_ms=4.0, loss=0.01)


def check_link(
    c: LinkConstraint,
    t: Thresholds,
    *,
    a: RobotView | None = None,
    b: RobotView | None = None,
    link: LinkStats | None = LINK,
    distance: float | None = 10.0,
) -> str | None:
    return c.check(a or robot("r1"), b or robot("r2"), link, distance, t)


@pytest.mark.parametrize(
    ("rssi_a", "rssi_b", "limit", "ok"),
    [
        (-45.0, -50.0, -52.5, True),
        (-45.0, -52.5, -52.5, False),  # at the threshold is not above it
        (-60.0, -45.0, -52.5, False),
        (None, -45.0, -52.5, True),  # no radio (wired): passes
        (-90.0, -90.0, None, True),
    ],
)
def test_rssi_above_on_both_ends(
    rssi_a: float | None, rssi_b: float | None, limit: float | None, ok: bool
):
    t = Thresholds(rssi_above_dbm=limit)
    why = check_link(RssiAbove(), t, a=robot("r1", rssi=rssi_a), b=robot("r2", rssi=rssi_b))
    assert (why is None) is ok
    if rssi_a == -60.0:
        assert why == "rssi of r1 -60dBm not above -52.5dBm"


@pytest.mark.parametrize(
    ("constraint", "thresholds", "bad_link", "reason"),
    [
        (
            JitterBelow(),
            Thresholds(jitter_below_ms=20.0),
            LinkStats(12.0, 25.0, 0.0),
            "jitter 25ms not below 20ms",
        ),
        (
            LossBelow(),
            Thresholds(loss_below=0.05),
            LinkStats(12.0, 1.0, 0.2),
            "loss 20.0% not below 5.0%",
        ),
        (
            DelayBelow(),
            Thresholds(delay_below_ms=100.0),
            LinkStats(150.0, 1.0, 0.0),
            "delay 150ms not below 100ms",
        ),
    ],
)
def test_measured_link_constraints(
    constraint: LinkConstraint, thresholds: Thresholds, bad_link: LinkStats, reason: str
):
    assert constraint.enabled(thresholds)
    assert check_link(constraint, thresholds) is None
    assert check_link(constraint, thresholds, link=bad_link) == reason
    # a threshold with nothing measured between the two robots fails
    assert check_link(constraint, thresholds, link=None) == "no link measurement"
    # no threshold: not checked, not even without a measurement
    assert not constraint.enabled(Thresholds())
    assert check_link(constraint, Thresholds(), link=None) is None


def test_measured_thresholds_are_strict():
    assert check_link(JitterBelow(), Thresholds(jitter_below_ms=4.0)) is not None
    assert check_link(DelayBelow(), Thresholds(delay_below_ms=12.0)) is not None
    assert check_link(LossBelow(), Thresholds(loss_below=0.01)) is not None


@pytest.mark.parametrize(
    ("distance", "limit", "ok"),
    [
        (10.0, 30.0, True),
        (30.0, 30.0, False),
        (45.5, 30.0, False),
        (None, 30.0, True),
        (99, None, True),
    ],
)
def test_distance_below(distance: float | None, limit: float | None, ok: bool):
    why = check_link(DistanceBelow(), Thresholds(distance_below_m=limit), distance=distance)
    assert (why is None) is ok
    if distance == 45.5:
        assert why == "distance 45.5m not below 30m"


# -- registry -------------------------------------------------------------------------------


def test_entry_points_name_every_builtin():
    for name in BUILTIN:
        c = CONSTRAINTS.get(name)
        assert c.name == name
    assert isinstance(CONSTRAINTS.get("memory"), MemFreeAbove)
    assert isinstance(STRATEGIES.get("first_fit"), FirstFit)
    assert isinstance(STRATEGIES.get("objective"), Objective)
    assert CONSTRAINTS.get("cpu") is CONSTRAINTS.get("cpu")  # loaded once


def test_active_constraints_follow_thresholds():
    robot_cs, link_cs = active_constraints((), Thresholds(battery_above_pct=1, rssi_above_dbm=-60))
    assert [c.name for c in robot_cs] == ["memory", "battery"]
    assert [c.name for c in link_cs] == ["rssi"]
    robot_cs, link_cs = active_constraints((), Thresholds())
    assert [c.name for c in robot_cs] == ["memory"]  # a capacity: always checked
    assert link_cs == []


def test_unknown_plugin_names_the_known_ones():
    with pytest.raises(
        ConfigError, match=r"unknown allocation constraint 'gpu' \(known: .*battery"
    ):
        CONSTRAINTS.get("gpu")
    with pytest.raises(ConfigError, match="unknown allocation strategy 'random'"):
        STRATEGIES.get("random")


class HasGpu(RobotConstraint):
    name = "gpu"
    static = True

    def check(self, load, need, component, t):
        return None if load.robot.name.startswith("gpu") else "no GPU"


def test_register_a_plugin_in_process():
    CONSTRAINTS.register("gpu", HasGpu)
    try:
        assert "gpu" in CONSTRAINTS.names()
        robot_cs, _ = active_constraints(("gpu",), Thresholds())
        assert [c.name for c in robot_cs] == ["memory", "gpu"]
        assert check_robot(robot_cs[1], robot("r1"), Thresholds()) == "no GPU"
    finally:
        CONSTRAINTS.unregister("gpu")
    assert "gpu" not in CONSTRAINTS.names()


def test_registry_refuses_the_wrong_kind():
    reg: Registry[RobotConstraint] = Registry(
        "sdrpeer.nothing", (RobotConstraint,), "allocation constraint"
    )
    with pytest.raises(ConfigError, match="is a str, not a RobotConstraint"):
        reg.register("x", "not a constraint")  # type: ignore[arg-type]
    assert reg.names() == []
