"""A composite's members in its instance status: listed in order, sharing its state, the one an
ERROR names marked `failed`; other instances list none."""

from __future__ import annotations

from sdrpeer.runtime.manager import composite_members
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.vocabulary import LifecycleState

PIPE = InstanceSpec.from_json(
    {"name": "Pipe", "launcher": "composite", "target": "periodic:5;Src=a.b:S;Dbl=a.b:D"}
)


def test_members_share_the_state_and_the_error_names_the_failed_one() -> None:
    error = "on_execute failed: member Dbl: on_execute: ValueError: cannot double 4"
    rows = composite_members(PIPE, LifecycleState.ERROR, error)["members"]
    assert [(r["name"], r["target"], r["state"], r["failed"]) for r in rows] == [
        ("Src", "a.b:S", "ERROR", False),
        ("Dbl", "a.b:D", "ERROR", True),
    ]
    active = composite_members(PIPE, LifecycleState.ACTIVE, error)["members"]
    assert [r["failed"] for r in active] == [False, False]  # an old error, not the state now


def test_an_ordinary_instance_lists_no_members() -> None:
    plain = InstanceSpec.from_json({"name": "Cam", "target": "a.b:C"})
    assert composite_members(plain, LifecycleState.ACTIVE, None) == {}
