"""A system file's `ros2:` connection ends (sdrpeer.system.ros2_ends), and the pure parts around
them: the bridge each end makes (its class from the port's type, QoS from the policy, standbys
from its peer), every mistake with file:line and field, the launchers an agent offers, the ROS 2
environment and discovery settings. No ROS 2 process runs here."""

from __future__ import annotations

import os

import pytest

from sdrpeer.errors import SystemFileError
from sdrpeer.launch.launchers import LAUNCHERS, offered
from sdrpeer.launch.policy import LaunchPolicy
from sdrpeer.ros2 import env
from sdrpeer.ros2.launcher import Ros2Launcher
from sdrpeer.sdk.robot_types import Pose
from sdrpeer.system.loader import parse_system
from sdrpeer.system.model import SystemDef

HEAD = """name: s
components:
  - {name: F, target: "components.odom_to_pose:OdomToPose", standby: {other_robots: 1}}
  - {name: U, target: "components.anomaly_detection:AnomalyDetection"}
connections:
"""
"""Lines 1-5; connections from line 6."""


def load(connections: str) -> SystemDef:
    return parse_system(HEAD + connections, "sys.yaml")


def test_ros2_ends_make_bridges_typed_by_their_ports() -> None:
    system = parse_system(
        HEAD
        + "  - {from: {ros2: /odom}, to: F.odom}\n"
        + "  - {from: F.pose, to: {ros2: /robot1/pose}, policy: {push: new, buffer: 1}}\n"
        + "  - {from: {ros2: /chatter, type: std_msgs/msg/String}, to: U.image}\n",
        "sys.yaml",
    )
    bridges = {c.name: c for c in system.components if c.launcher == "ros2"}
    sub, pub, chat = (
        bridges["ros2-odom-sub"],
        bridges["ros2-robot1_pose-pub"],
        bridges["ros2-chatter-sub"],
    )
    assert sub.target == "sdrpeer.ros2.bridge:FromRosOdometry"
    assert sub.params_map() == {
        "topic": "/odom",
        "depth": 10,
        "reliability": "reliable",
        "durability": "volatile",
    }
    assert sub.standby.other_robots == 1  # F's standbys: the bridge fails over with it
    assert pub.target == "sdrpeer.ros2.bridge:ToRosPose"
    assert pub.params_map()["reliability"] == "best_effort"  # push: new
    assert pub.params_map()["depth"] == 1  # buffer: 1
    assert chat.target == "sdrpeer.ros2.bridge:FromRos"  # any ROS type: untyped maps
    assert chat.params_map()["ros_type"] == "std_msgs/msg/String"
    ids = {c.id for c in system.connections}
    assert ids == {
        "ros2-odom-sub.out->F.odom",
        "F.pose->ros2-robot1_pose-pub.input",
        "ros2-chatter-sub.out->U.image",
    }


def test_two_connections_of_one_topic_share_its_bridge() -> None:
    system = parse_system(
        HEAD.replace(
            "components:\n",
            'components:\n  - {name: G, target: "components.odom_to_pose:OdomToPose", '
            "standby: {other_robots: 2}}\n",
        )
        + "  - {from: {ros2: /odom}, to: F.odom}\n"
        + "  - {from: {ros2: /odom}, to: G.odom}\n",
        "sys.yaml",
    )
    bridges = [c for c in system.components if c.launcher == "ros2"]
    assert [c.name for c in bridges] == ["ros2-odom-sub"]
    assert bridges[0].standby.other_robots == 2  # the more guarded peer's
    assert len(system.connections) == 2


def test_qos_given_on_the_end_wins() -> None:
    system = load(
        "  - {from: {ros2: /odom, qos: {reliability: best_effort, depth: 3,"
        " durability: transient_local}}, to: F.odom}\n"
    )
    bridge = next(c for c in system.components if c.launcher == "ros2")
    assert bridge.params_map() == {
        "topic": "/odom",
        "depth": 3,
        "reliability": "best_effort",
        "durability": "transient_local",
    }


@pytest.mark.parametrize(
    ("connections", "expected"),
    [
        (
            "  - {from: {ros2: odom}, to: F.odom}\n",
            "sys.yaml:6: field 'connections[0].from.ros2': expected an absolute ROS 2 topic name",
        ),
        (
            "  - {from: {ros2: /odom}, to: {ros2: /pose}}\n",
            "sys.yaml:6: field 'connections[0]': both ends are ROS 2 topics",
        ),
        (
            "  - {from: {ros2: /odom, type: Pose}, to: F.odom}\n",
            "field 'connections[0].from.type': Pose is geometry_msgs/msg/PoseStamped but the port "
            "carries Odometry",
        ),
        (
            "  - {from: {ros2: /odom}, to: U.image}\n",
            "field 'connections[0].from.type': missing: the sdrpeer end's type is not known here",
        ),
        (
            "  - {from: {ros2: /odom, type: Lidar}, to: U.image}\n",
            "field 'connections[0].from.type': Lidar is not a standard type",
        ),
        (
            "  - {from: {ros2: /odom, qos: {reliability: sometimes}}, to: F.odom}\n",
            "field 'connections[0].from.qos.reliability': expected reliable, best_effort",
        ),
        (
            "  - {from: {ros2: /odom, qos: {depth: 0}}, to: F.odom}\n",
            "field 'connections[0].from.qos.depth': expected an integer >= 1",
        ),
        (
            "  - {from: {ros2: /odom, colour: red}, to: F.odom}\n",
            "field 'connections[0].from.colour': unknown field (known: ros2, type, qos)",
        ),
        (
            "  - {from: {ros2: /odom}, to: F.nope}\n",
            "field 'connections[0].to': OdomToPose has no port 'nope'",
        ),
        (
            "  - {from: {ros2: /robot/odom}, to: F.odom}\n"
            "  - {from: {ros2: /robot_odom}, to: F.odom}\n",
            "sys.yaml:7: field 'connections[1].from': /robot_odom and /robot/odom (line 6) make "
            "one bridge name, ros2-robot_odom-sub",
        ),
        (
            "  - {from: {ros2: /odom}, to: F.odom}\n"
            "  - {from: {ros2: /odom, qos: {depth: 2}}, to: F.odom}\n",
            "sys.yaml:7: field 'connections[1].from': /odom is bridged from ROS 2 at line 6 with "
            "another type or QoS",
        ),
    ],
)
def test_a_wrong_ros2_end_is_reported_with_its_line_and_field(
    connections: str, expected: str
) -> None:
    with pytest.raises(SystemFileError) as info:
        load(connections)
    assert expected in str(info.value)


def test_a_port_of_an_unmapped_type_cannot_be_bridged() -> None:
    text = (
        'name: s\ncomponents:\n  - {name: T, target: "tests.typed_fixture:DetectionSource"}\n'
        "connections:\n  - {from: T.out, to: {ros2: /det}}\n"
    )
    with pytest.raises(SystemFileError) as info:
        parse_system(text, "sys.yaml")
    assert "which has no ROS 2 mapping" in str(info.value)


class _Unavailable:
    name = "ros2"

    def command(self, target: object, params: object, *, python: str) -> list[str]:
        return []

    def available(self) -> str:
        return "ROS 2 is not installed here"


def test_an_agent_offers_only_the_launchers_it_can_run(monkeypatch: pytest.MonkeyPatch) -> None:
    policy = LaunchPolicy(("python", "ros2", "exec"))
    assert offered(policy) == (policy, {})  # ROS 2 is installed in the test environment
    monkeypatch.setattr(env, "available", lambda: "ROS 2 is not installed here (pip ...)")
    kept, missing = offered(policy)
    assert kept.launchers == ("python", "exec")
    assert missing == {"ros2": "ROS 2 is not installed here (pip ...)"}
    assert kept.refusal("ros2", "components.ros2.odometry:OdometryPublisher") is not None


def test_ros2_targets_are_held_to_allow_targets() -> None:
    policy = LaunchPolicy(("python", "ros2"), ("components.*",))
    assert policy.refusal("ros2", "components.ros2.odometry:OdometryPublisher") is None
    why = policy.refusal("ros2", "evil.node:Node")
    assert why is not None
    assert why.startswith("ros2 target 'evil.node:Node'")


def test_the_launcher_runs_the_ros2_host() -> None:
    argv = Ros2Launcher().command("pkg.mod:Node", {"rate_hz": 50.0}, python="/py")
    assert argv == ["/py", "-m", "sdrpeer.ros2.host", "pkg.mod:Node", "--param", "rate_hz=50.0"]
    assert isinstance(LAUNCHERS.get("ros2"), Ros2Launcher)


def test_the_process_environment_finds_the_wheels_libraries(tmp_path: object) -> None:
    base = {"LD_LIBRARY_PATH": "/opt/x", "AMENT_PREFIX_PATH": "/opt/ros"}
    out = env.process_env(base, env.Ros2Net(7, ("10.0.0.2", "127.0.0.1", "10.0.0.3")))
    parts = out["LD_LIBRARY_PATH"].split(os.pathsep)
    assert parts[-1] == "/opt/x"
    assert len(parts) == len(set(parts)) > 1
    assert out["_ROS_WHEELS_BOOTSTRAP_COMPLETE"] == "1"
    assert out["AMENT_PREFIX_PATH"].endswith(os.pathsep + "/opt/ros")
    assert out["ROS_DOMAIN_ID"] == "7"
    assert out["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert out["ROS_STATIC_PEERS"] == "10.0.0.2;10.0.0.3"  # loopback needs no static peer
    assert "ROS_STATIC_PEERS" not in env.process_env({}, env.Ros2Net(7, ("127.0.0.1",)))


def test_a_fleets_default_domain_is_stable_and_never_zero() -> None:
    domains = {env.default_domain(name) for name in ("sdrpeer", "a", "b", "lava-tube")}
    assert all(1 <= d <= env.DOMAIN_MAX for d in domains)
    assert env.default_domain("sdrpeer") == env.default_domain("sdrpeer")


def test_a_ros2_file_target_needs_the_script_launcher_too() -> None:
    policy = LaunchPolicy(("python", "ros2"))
    why = policy.refusal("ros2", "/tmp/anything.py:Node")
    assert why is not None
    assert "needs the script launcher allowed too" in why
    assert policy.refusal("ros2", "nodes/talker.py") is not None
    assert LaunchPolicy(("python", "ros2", "script")).refusal("ros2", "nodes/talker.py") is None
    assert policy.refusal("ros2", "components.ros2.odometry:OdometryPublisher") is None


def test_a_bridge_drops_and_counts_a_message_that_does_not_decode() -> None:
    from sdrpeer.ros2.bridge import FromRosPose  # noqa: PLC0415 - imports no rclpy
    from sdrpeer.ros2.cdr import decoder_for  # noqa: PLC0415

    bridge = FromRosPose("B", {"topic": "/p"})
    decode = decoder_for(Pose)
    assert decode is not None
    bridge._decode_raw = decode
    bridge._active = True
    bridge._heard_raw(b"\x00\x01\x00\x00garbage")  # in rclpy's thread this must not raise
    bridge._heard_raw(b"\x00\x01\x00\x00" + bytes(12) + b"\xff\xff\xff\x7f")  # a string too long
    assert bridge.malformed == 2
    assert not bridge._batch
    assert bridge.port_counters()["/p"] == {"frames_in": 0, "malformed": 2}
