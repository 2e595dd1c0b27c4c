"""How a port reference is split into instance and port: at the instance this agent hosts or the
cluster lists (a composite member's port holds a dot), else at the last dot."""

from __future__ import annotations

from typing import Any, cast

import pytest

from sdrpeer.errors import PortToolError
from sdrpeer.ports.catalog import Catalog
from sdrpeer.runtime.manager import InstanceManager


class Desired:
    """The one thing a Catalog asks of its manager here: the desired set's names."""

    def __init__(self, *names: str) -> None:
        self.names = names

    def desired(self) -> dict[str, Any]:
        return dict.fromkeys(self.names)


def catalog(*hosted: str, elsewhere: tuple[str, ...] = ()) -> Catalog:
    manager = cast(InstanceManager, Desired(*hosted))
    return Catalog(manager, "robot-1", lambda n: ("robot-2", None) if n in elsewhere else None)


def test_a_composite_members_port_is_split_at_the_known_instance() -> None:
    c = catalog("Perception", "Cam1.left")
    assert c.split("Perception.Cam.image") == ("Perception", "Cam.image")
    assert c.split("Cam1.left.image") == ("Cam1.left", "image")  # a dotted instance name
    assert catalog(elsewhere=("Perception",)).split("Perception.Det.alarm") == (
        "Perception",
        "Det.alarm",
    )


def test_an_unknown_instance_is_split_at_the_last_dot_and_a_bad_form_refused() -> None:
    assert catalog().split("Nobody.Cam.image") == ("Nobody.Cam", "image")
    for bad in ("image", "Cam.", "Cam.1x"):
        with pytest.raises(PortToolError, match=r"expected Instance\.port"):
            catalog().split(bad)


def test_a_composites_member_ports_keep_their_message_types() -> None:
    from sdrpeer.ports.catalog import _class_ports  # noqa: PLC0415 - the class reading itself

    target = "stepped;Pub=tests.typed_fixture:PosePub;Rec=tests.typed_fixture:PoseRec"
    ports = _class_ports("composite", target)
    assert ports is not None
    kinds = {name: (kind, None if m is None else m.name) for name, (kind, m, _) in ports.items()}
    assert kinds["Pub.pose"] == ("out", "sdrpeer/Pose")
    assert kinds["Rec.pose"] == ("in", "sdrpeer/Pose")


def test_service_ports_are_listed_with_their_role_and_interface() -> None:
    from components.planner import PLANNER  # noqa: PLC0415
    from sdrpeer.ports.catalog import _class_ports  # noqa: PLC0415

    provider = _class_ports("python", "components.planner:PathPlanner")
    caller = _class_ports("python", "components.planner:PlanCaller")
    assert provider is not None
    assert caller is not None
    assert provider["planner"] == ("provides", None, PLANNER.id)
    assert caller["planner"] == ("requires", None, PLANNER.id)
    assert caller["path"][0] == "out"
