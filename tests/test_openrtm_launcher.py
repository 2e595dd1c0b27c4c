"""The `openrtm` launcher's command, what it and the agent say when OpenRTM is not installed, and
the OpenRTM <-> sdrpeer value mapping (docs/openrtm.md)."""

from __future__ import annotations

import math
import subprocess
import sys
from collections.abc import Iterator

import pytest

from sdrpeer.config import AgentConfig
from sdrpeer.errors import LauncherError, RtcDataError
from sdrpeer.launch import openrtm
from sdrpeer.launch.launchers import get_launcher, known_launchers, offered
from sdrpeer.sdk import Pose, Velocity

needs_openrtm = pytest.mark.skipif(openrtm.available() is not None, reason=f"{openrtm.available()}")


@pytest.fixture
def no_openrtm(monkeypatch: pytest.MonkeyPatch) -> Iterator[None]:
    """OpenRTM_aist cannot be imported (find_spec answers None for a None in sys.modules)."""
    monkeypatch.setitem(sys.modules, "OpenRTM_aist", None)
    openrtm.available.cache_clear()
    yield
    openrtm.available.cache_clear()


def test_openrtm_is_a_launcher() -> None:
    assert "openrtm" in known_launchers()


@needs_openrtm
def test_the_command_runs_the_openrtm_host_with_the_rtcs_configuration() -> None:
    argv = get_launcher("openrtm").command("rtcs/Camera.py:Camera", {"rate": 5}, python="py")
    assert argv == ["py", "-m", "sdrpeer.openrtm", "rtcs/Camera.py:Camera", "--param", "rate=5"]
    with pytest.raises(LauncherError, match="target must be"):
        get_launcher("openrtm").command(["a", "b"], {}, python="py")


@pytest.mark.usefixtures("no_openrtm")
def test_without_openrtm_the_launcher_says_so_and_how_to_install_it() -> None:
    with pytest.raises(LauncherError) as err:
        get_launcher("openrtm").command("rtcs/Camera.py", {}, python="py")
    text = str(err.value)
    assert "OpenRTM-aist-Python is not installed here (no module OpenRTM_aist)" in text
    assert "pip install 'sdrpeer[openrtm]' --find-links third_party/wheels" in text


@pytest.mark.usefixtures("no_openrtm")
def test_without_openrtm_an_agent_does_not_offer_the_launcher() -> None:
    config = AgentConfig(name="r1", allow_launchers=("openrtm", "exec"))
    policy, missing = offered(config.launch_policy)
    assert policy.launchers == ("python", "exec")  # gossiped: no RTC placed here
    assert "OpenRTM-aist-Python is not installed here" in missing["openrtm"]
    assert "launcher 'openrtm' is off" in str(policy.refusal("openrtm", "x.py"))


@needs_openrtm
def test_with_openrtm_an_agent_offers_it_when_allowed() -> None:
    config = AgentConfig(name="r1", allow_launchers=("openrtm",))
    assert offered(config.launch_policy)[0].launchers == ("python", "openrtm")
    assert offered(AgentConfig(name="r1").launch_policy)[0].launchers == ("python",)


def test_the_openrtm_host_without_openrtm_exits_2_saying_why() -> None:
    code = (
        "import sys; sys.modules['OpenRTM_aist'] = None\n"
        "from sdrpeer.openrtm.host import main\n"
        "raise SystemExit(main(['tests.rtc_fixture:Relay']))\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 2
    assert "sdrpeer.openrtm: OpenRTM-aist-Python is not installed here" in done.stderr


@needs_openrtm
def test_pose_and_velocity_map_to_the_robot_types_and_back() -> None:
    from sdrpeer.openrtm.values import from_sdrpeer, to_sdrpeer  # noqa: PLC0415 - needs omniORB

    pose = Pose(stamp=1700000000.25, frame="map", x=1.5, y=-2.0, qz=math.sin(0.3), qw=math.cos(0.3))
    data = from_sdrpeer(pose, "IDL:RTC/TimedPose2D:1.0")
    assert (data.tm.sec, data.tm.nsec) == (1700000000, 250_000_000)
    assert (data.data.position.x, data.data.position.y) == (1.5, -2.0)
    assert data.data.heading == pytest.approx(0.6)
    back = to_sdrpeer(data, "IDL:RTC/TimedPose2D:1.0")
    assert (back.stamp, back.frame, back.x, back.y) == (1700000000.25, "", 1.5, -2.0)
    assert (back.qz, back.qw) == (pytest.approx(pose.qz), pytest.approx(pose.qw))
    vel = from_sdrpeer(Velocity(stamp=5.0, frame="", vx=0.5, wz=0.1), "IDL:RTC/TimedVelocity2D:1.0")
    assert (vel.data.vx, vel.data.vy, vel.data.va) == (0.5, 0.0, 0.1)
    assert to_sdrpeer(vel, "IDL:RTC/TimedVelocity2D:1.0") == Velocity(5.0, "", 0.5, wz=0.1)


@needs_openrtm
@pytest.mark.parametrize(
    ("repo", "value"),
    [
        ("IDL:RTC/TimedLong:1.0", 42),
        ("IDL:RTC/TimedDouble:1.0", 2.5),
        ("IDL:RTC/TimedBoolean:1.0", True),
        ("IDL:RTC/TimedString:1.0", "hello"),
        ("IDL:RTC/TimedOctetSeq:1.0", b"\x00\x01\xff"),
        ("IDL:RTC/TimedDoubleSeq:1.0", [1.0, -2.5]),
        ("IDL:RTC/TimedLongSeq:1.0", [3, 4]),
    ],
)
def test_simple_timed_types_are_their_data(repo: str, value: object) -> None:
    from sdrpeer.openrtm.values import from_sdrpeer, to_sdrpeer  # noqa: PLC0415

    data = from_sdrpeer(value, repo)
    assert data.tm.sec > 0  # stamped when written, as OpenRTM_aist.setTimestamp does
    assert to_sdrpeer(data, repo) == value


@needs_openrtm
def test_other_structs_are_maps_of_their_fields_with_times_in_seconds() -> None:
    from sdrpeer.openrtm.values import from_sdrpeer, to_sdrpeer  # noqa: PLC0415

    value = {"tm": 12.5, "data": {"x": 1.0, "y": 2.0, "z": 3.0}}
    data = from_sdrpeer(value, "IDL:RTC/TimedPoint3D:1.0")
    assert to_sdrpeer(data, "IDL:RTC/TimedPoint3D:1.0") == value
    missing = to_sdrpeer(
        from_sdrpeer({"data": {"x": 1.0}}, "IDL:RTC/TimedPoint3D:1.0"), "IDL:RTC/TimedPoint3D:1.0"
    )
    assert missing["data"] == {"x": 1.0, "y": 0.0, "z": 0.0}
    with pytest.raises(RtcDataError, match="TimedLong"):
        from_sdrpeer("not a number", "IDL:RTC/TimedLong:1.0")
