"""POST /v1/deploy's answers when a system cannot be placed: 409 with the report when every robot
the allocator hears has been heard from in full, 503 ("retry in a moment", which the CLI does)
while a robot that just joined is alive but its record has not arrived yet."""

from __future__ import annotations

from typing import Any

from aiohttp.test_utils import TestClient, TestServer

from sdrpeer.alloc.result import Infeasible, Unplaced
from sdrpeer.api.app import build_app
from sdrpeer.deploy.routes import ROUTES
from sdrpeer.deploy.view import ClusterState
from sdrpeer.system.model import ComponentDef, ConnectionDef, SystemDef
from tests.test_deploy_core import SYSTEM, record
from tests.test_runtime_api import View as AgentStub

TOKEN = "tok"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
REFUSED = Infeasible(
    "s", (Unplaced("A", "A-s1", "standby", (("r1", "already holds A"),)),), robots=1
)


class Coordinator:
    """The allocator as the route sees it: it refuses the system, and hears `heard`."""

    name = "r1"

    def __init__(self, heard: frozenset[str]) -> None:
        self.state = ClusterState({"r1": record("r1")}, ["r1"], heard, heard)

    def cluster(self) -> ClusterState:
        return self.state

    async def deploy(self, system: SystemDef | None, origin: str) -> Infeasible:
        return REFUSED


class View(AgentStub):
    def __init__(self, coordinator: Coordinator) -> None:
        super().__init__(None)
        self.coordinator = coordinator


async def post_deploy(
    heard: frozenset[str], system: SystemDef = SYSTEM
) -> tuple[int, dict[str, Any]]:
    app = build_app(View(Coordinator(heard)), token=TOKEN, extra_routes=ROUTES)
    async with TestClient(TestServer(app)) as client:
        resp = await client.post("/v1/deploy", json={"system": system.to_json()}, headers=AUTH)
        return resp.status, await resp.json()


async def test_an_infeasible_system_is_refused_with_the_report() -> None:
    code, body = await post_deploy(frozenset({"r1"}))
    assert code == 409
    assert "r1: already holds A" in body["error"]
    assert body["report"] == str(REFUSED)


async def test_a_robot_alive_without_its_record_makes_it_retry_not_refuse() -> None:
    code, body = await post_deploy(frozenset({"r1", "r2"}))
    assert code == 503  # the CLI retries 503 (sdrpeer.client.post_when_elected)
    assert "r2 alive but not heard from in full" in body["error"]
    assert "r1: already holds A" in body["error"]  # the report as it stands now


async def test_a_document_whose_connections_the_classes_refuse_is_refused() -> None:
    """A system document posted as it is (no loader saw it) is checked against the classes."""
    publisher = ComponentDef("Pub", "python", "tests.typed_fixture:PosePub")
    images = ComponentDef("Rec", "python", "tests.typed_fixture:ImageRec")
    caller = ComponentDef("Caller", "python", "components.planner:PlanCaller")
    elsewhere = ComponentDef("Far", "python", "not_on_this_robot.mod:Thing")
    system = SystemDef(
        "s",
        (publisher, images, caller, elsewhere),
        (
            ConnectionDef("Pub", "pose", "Rec", "image"),
            ConnectionDef("Caller", "planner", "Rec", "image"),
            ConnectionDef("Pub", "pose", "Far", "inp"),  # not importable here: not judged
        ),
    )
    code, body = await post_deploy(frozenset({"r1"}), system)
    assert code == 409
    assert "Pub.pose sends sdrpeer/Pose#" in body["error"]
    assert "but Rec.image takes sdrpeer/Image#" in body["error"]
    assert "Caller.planner is a service port but Rec.image is a data port" in body["error"]
    assert "Far" not in body["error"]
