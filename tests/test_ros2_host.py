"""Unmodified rclpy nodes hosted by `python -m sdrpeer.ros2.host`, driven through the control
channel as the agent drives them: the RTC lifecycle drives a lifecycle node's transitions and a
plain node's life, a node's endpoints and traffic reach the heartbeats, and a node that raises,
blocks or cannot be made ends in ERROR. A ROS 2 probe in the test process watches the graph."""

from __future__ import annotations

import itertools
import time
from collections.abc import Iterator

import pytest
from lifecycle_msgs.srv import GetState
from nav_msgs.msg import Odometry
from std_msgs.msg import String

from tests.hostctl import HostPool, HostProc, Msg
from tests.ros2_probe import Probe
from tests.wait import until

ROS = "sdrpeer.ros2.host"
TALKER = "components.ros2.lifecycle_talker:LifecycleTalker"
ODOM = "components.ros2.odometry:OdometryPublisher"
WITHIN = 20.0


@pytest.fixture
def probe() -> Iterator[Probe]:
    p = Probe()
    try:
        yield p
    finally:
        p.close()


def lifecycle_state(probe: Probe) -> str:
    return str(
        probe.call("/lifecycle_talker/get_state", GetState, GetState.Request()).current_state.label
    )


def beat_with(host: HostProc, name: str) -> Msg:
    return host.wait_for(
        lambda m: m["t"] == "heartbeat" and (m.get("endpoints") or {}).get(name) is not None,
        WITHIN,
        f"a heartbeat listing {name}",
    )


def test_a_lifecycle_node_follows_the_rtc_lifecycle(hosts: HostPool, probe: Probe) -> None:
    host, hello = hosts.ready(TALKER, name="Talker", module=ROS)
    assert hello["component"] == "LifecycleTalker"
    # INACTIVE: configured by initialize, not active; its lifecycle publisher sends nothing
    assert (
        until(
            "the node's state",
            lambda: lifecycle_state(probe),
            lambda s: s == "inactive",
            within=WITHIN,
            retry=(AssertionError,),
        )
        == "inactive"
    )
    probe.listen("/chatter", String)
    assert host.command("activate")["ok"] is True
    assert lifecycle_state(probe) == "active"
    until("chatter", lambda: len(probe.messages("/chatter")), lambda n: n >= 5, within=WITHIN)
    beat = beat_with(host, "/chatter")
    assert beat["endpoints"]["/chatter"] == ["publishes", "std_msgs/msg/String"]
    until(
        "counted chatter",
        lambda: host.wait_t("heartbeat", WITHIN)["ports"]["/chatter"]["frames_out"],
        lambda n: n >= 5,
        within=WITHIN,
    )
    assert host.command("deactivate")["ok"] is True
    assert lifecycle_state(probe) == "inactive"
    quiet_from = time.time() + 0.5  # what was on the way has arrived by then
    host.wait_t("heartbeat", WITHIN)
    host.wait_t("heartbeat", WITHIN)
    assert probe.messages("/chatter", since=quiet_from) == []
    assert host.command("exit")["ok"] is True
    assert host.wait_exit(10.0) == 0


def test_a_plain_node_lives_while_active_and_takes_its_params(
    hosts: HostPool, probe: Probe
) -> None:
    host, _ = hosts.ready(
        ODOM, "--param", "rate_hz=10.0", "--param", "speed=2.0", name="Odom", module=ROS
    )
    probe.listen("/odom", Odometry)
    assert "odometry_publisher" not in probe.node_names()  # a standby: rclpy up, no node yet
    assert host.command("activate")["ok"] is True
    msgs = until("odometry", lambda: probe.messages("/odom"), lambda m: len(m) >= 4, within=WITHIN)
    steps = {
        round(b.pose.pose.position.x - a.pose.pose.position.x, 6)
        for a, b in itertools.pairwise(msgs)
    }
    assert steps == {0.2}  # speed / rate_hz: the ROS parameters reached the node
    assert "odometry_publisher" in probe.node_names()
    assert beat_with(host, "/odom")["endpoints"]["/odom"] == ["publishes", "nav_msgs/msg/Odometry"]
    assert host.command("deactivate")["ok"] is True
    until("the node gone", probe.node_names, lambda n: "odometry_publisher" not in n, within=WITHIN)
    assert host.command("activate")["ok"] is True  # made again
    until("the node back", probe.node_names, lambda n: "odometry_publisher" in n, within=WITHIN)


@pytest.mark.parametrize(
    ("target", "args", "error"),
    [
        ("tests.ros2_nodes:Raising", (), "executor stopped"),
        ("tests.ros2_nodes:Blocking", ("--param", "stuck_after=0.5"), "in one callback"),
    ],
)
def test_a_node_that_raises_or_blocks_goes_to_error(
    hosts: HostPool, target: str, args: tuple[str, ...], error: str
) -> None:
    host, _ = hosts.ready(target, *args, name="Bad", module=ROS)
    assert host.command("activate")["ok"] is True
    report = host.wait_for(lambda m: m["t"] == "state" and m["state"] == "ERROR", WITHIN, "ERROR")
    assert error in report["error"]
    # a dead or stuck executor cannot be reset (recovery restarts the host instead), and
    # neither the reset nor the exit waits behind the callback that never returns
    assert host.command("reset", timeout=WITHIN)["ok"] is False
    assert host.command("exit", timeout=WITHIN)["ok"] is True
    assert host.wait_exit(WITHIN) in (0, 1)


def test_a_service_bridge_offers_its_service_only_while_active(
    hosts: HostPool, probe: Probe
) -> None:
    host, _ = hosts.ready(
        "sdrpeer.ros2.services:FromRosService",
        "--param",
        "service=/standby_test",
        "--param",
        "srv_type=std_srvs/srv/SetBool",
        name="Svc",
        module=ROS,
    )

    def services() -> list[str]:
        if "Svc" not in probe.node_names():
            return ["(node not seen yet)"]
        return [n for n, _ in probe.node.get_service_names_and_types_by_node("Svc", "/")]

    assert "/standby_test" not in until(
        "the standby's node in the graph",
        services,
        lambda s: "(node not seen yet)" not in s,
        within=WITHIN,
    )
    assert host.command("activate")["ok"] is True
    until("the service offered", services, lambda s: "/standby_test" in s, within=WITHIN)
    assert host.command("deactivate")["ok"] is True
    until("the service withdrawn", services, lambda s: "/standby_test" not in s, within=WITHIN)


def test_a_node_that_cannot_be_made_refuses_to_activate(hosts: HostPool) -> None:
    host, _ = hosts.ready("tests.ros2_nodes:Failing", name="Bad", module=ROS)
    reply = host.command("activate")
    assert reply["ok"] is False
    assert "no such device" in reply["error"]


def test_a_target_that_is_neither_a_node_nor_a_component_is_refused(hosts: HostPool) -> None:
    host = hosts.spawn("tests.ros2_probe:Probe", name="NotANode", module=ROS)
    assert host.wait_exit(20.0) == 2
    assert "is not a subclass of Component or Node" in host.log_text()
