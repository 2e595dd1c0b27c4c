"""The disconnect policy's pure parts: quorum, the cut-off robot's side, the fleet's side, the
system file's `disconnect:` block, and held components in the allocation core."""

from __future__ import annotations

import math

import pytest

from sdrpeer.alloc.core import allocate
from sdrpeer.alloc.view import ClusterView
from sdrpeer.deploy.disconnect import CutOff, fleet_of, has_quorum, held_components
from sdrpeer.deploy.plan_change import with_origins
from sdrpeer.deploy.view import ClusterState
from sdrpeer.errors import ConfigError
from sdrpeer.plan import Placement, Plan, plan_from_json
from sdrpeer.system.loader import parse_system
from sdrpeer.system.model import DisconnectSpec, StandbySpec, SystemDef, system_from_json
from sdrpeer.vocabulary import InstanceRole
from tests.test_alloc_core import TABLE_V, comp, robot

# -- quorum ----------------------------------------------------------------------------------


def test_a_strict_majority_holds_the_quorum_and_a_minority_does_not():
    fleet = {f"robot-{k}" for k in range(1, 6)}
    assert has_quorum("robot-1", {"robot-1", "robot-2", "robot-3"}, fleet)
    assert not has_quorum("robot-4", {"robot-4", "robot-5"}, fleet)
    assert not has_quorum("robot-3", {"robot-3"}, fleet)


def test_an_even_split_keeps_the_quorum_on_the_half_with_the_first_name_only():
    fleet = {"robot-1", "robot-2", "robot-3", "robot-4"}
    assert has_quorum("robot-2", {"robot-1", "robot-2"}, fleet)
    assert not has_quorum("robot-3", {"robot-3", "robot-4"}, fleet)
    assert has_quorum("robot-1", set(), {"robot-1", "robot-2"})
    assert not has_quorum("robot-2", set(), {"robot-1", "robot-2"})


def test_a_fleet_of_one_and_robots_heard_beyond_the_table_count():
    assert has_quorum("robot-1", set(), {"robot-1"})
    # a robot heard but not (yet) in the table still counts on both sides of the fraction
    assert has_quorum("robot-1", {"robot-9"}, {"robot-1", "robot-2"})


def plan_on(*robots: str) -> Plan:
    placements = tuple(
        Placement(f"C{k}", f"C{k}", r, InstanceRole.ACTIVE, "hot") for k, r in enumerate(robots)
    )
    return Plan(4, 2, None, placements, "robot-1")


def test_a_restarted_robot_counts_its_plans_robots_until_it_hears_of_another():
    plan = plan_on("robot-1", "robot-2", "robot-3")
    alone = fleet_of("robot-3", {"robot-3"}, plan, heard_of_others=False)
    assert alone == {"robot-1", "robot-2", "robot-3"}
    assert not has_quorum("robot-3", {"robot-3"}, alone)
    # once it has heard of the others, the table is the fleet (the plan may be stale)
    joined = fleet_of("robot-3", {"robot-2", "robot-3", "robot-4"}, plan, heard_of_others=True)
    assert joined == {"robot-2", "robot-3", "robot-4"}
    # with nothing deployed a robot alone is a fleet of one
    assert fleet_of("robot-3", {"robot-3"}, None, heard_of_others=False) == {"robot-3"}


# -- the robot side ------------------------------------------------------------------------

NOW = DisconnectSpec()
LATER = DisconnectSpec(stop_after_s=5.0)
NEVER = DisconnectSpec(stop_after_s=None, replace=False)


def test_a_cut_off_robot_holds_each_active_down_after_its_stop_after():
    c = CutOff()
    assert not c.update(10.0, quorum=True, caught_up=True)
    assert not c.holds_down(10.0, NOW)
    assert c.update(11.0, quorum=False, caught_up=True)
    assert c.cut
    assert c.holds_down(11.0, NOW)
    assert not c.holds_down(15.9, LATER)
    assert c.next_timer([NOW, LATER, NEVER]) == 11.0
    assert c.next_timer([LATER, NEVER]) == 16.0
    assert c.holds_down(16.0, LATER)
    assert not c.holds_down(1000.0, NEVER)
    assert not c.update(12.0, quorum=False, caught_up=True)  # still cut: no change


def test_back_in_touch_it_keeps_them_down_until_it_has_caught_up_with_the_plan():
    c = CutOff()
    c.update(0.0, quorum=False, caught_up=True)
    assert c.update(3.0, quorum=True, caught_up=False)
    assert not c.cut
    assert c.rejoining
    assert c.holds_down(3.0, NOW)  # cut for 3 s: the fleet has replaced it
    assert not c.holds_down(3.0, LATER)  # cut for less than its 5 s: never stopped
    assert c.next_timer([NOW]) == math.inf
    assert not c.update(4.0, quorum=True, caught_up=False)
    assert c.update(4.5, quorum=True, caught_up=True)
    assert (c.rejoining, c.holds_down(4.5, NOW)) == (False, False)


# -- the fleet side ------------------------------------------------------------------------


def two_components(a: DisconnectSpec, b: DisconnectSpec) -> Plan:
    system = SystemDef("s", (comp("A", disconnect=a), comp("B", disconnect=b)), allocation=TABLE_V)
    placements = (
        Placement("A", "A", "robot-2", InstanceRole.ACTIVE, "hot"),
        Placement("B", "B", "robot-2", InstanceRole.ACTIVE, "hot"),
    )
    return Plan(1, 1, system, placements, "robot-1")


def test_the_fleet_waits_lost_after_and_never_replaces_what_it_may_not():
    plan = two_components(DisconnectSpec(lost_after_s=4.0), DisconnectSpec(replace=False))
    alive = {"robot-1", "robot-3"}
    held, due = held_components(plan, alive, {"robot-2": 10.0}, 12.0)
    assert held == {"A", "B"}
    assert due == 14.0
    held, due = held_components(plan, alive, {"robot-2": 10.0}, 14.0)
    assert held == {"B"}
    assert due == math.inf
    # robot-2 alive again: nothing is held
    assert held_components(plan, alive | {"robot-2"}, {}, 14.0) == (frozenset(), math.inf)
    # alive but degraded (robot-wide recovery moves its components): B, tied to it, stays
    back = alive | {"robot-2"}
    assert held_components(plan, back, {}, 14.0, degraded={"robot-2"}) == (
        frozenset({"B"}),
        math.inf,
    )


def test_held_components_keep_their_placements_off_the_view_and_the_rest_moves():
    system = SystemDef(
        "s",
        (
            comp("A", disconnect=DisconnectSpec(replace=False), standby=StandbySpec(0, 1)),
            comp("B", standby=StandbySpec(0, 1)),
        ),
        allocation=TABLE_V,
    )
    names = ("robot-1", "robot-2", "robot-3")
    view = ClusterView(tuple(robot(r) for r in names), None)
    first = allocate(system, view, epoch=1, version=1, allocator="robot-1")
    assert first.plan is not None
    before = {(p.instance, p.robot, p.role) for p in first.plan.placements}
    lost = first.plan.active_of("A")
    assert lost is not None
    rest = ClusterView(tuple(robot(r) for r in names if r != lost.robot), None)
    again = allocate(system, rest, epoch=1, version=2, allocator="robot-1", previous=first.plan,
                     held={"A"})  # fmt: skip
    assert again.plan is not None, again.infeasible
    after = {(p.instance, p.robot, p.role) for p in again.plan.placements}
    kept_a = {x for x in before if x[0].startswith("A")}
    assert kept_a <= after  # A stays on its lost robot, with its standby where it was
    b = again.plan.active_of("B")
    assert b is not None
    assert b.robot != lost.robot  # B, not held, left the lost robot


# -- the system file -----------------------------------------------------------------------

BASE = """name: s
components:
  - name: A
    target: components.camera:Camera
"""


def test_the_disconnect_block_is_read_with_its_defaults():
    s = parse_system(BASE, "s.yaml")
    assert s.component("A").disconnect == DisconnectSpec(0.0, True, 0.0, "keep_replacement")
    s = parse_system(BASE + "    disconnect: {replace: false}\n", "s.yaml")
    assert s.component("A").disconnect == DisconnectSpec(None, False, 0.0, "keep_replacement")
    s = parse_system(
        BASE + "    disconnect: {stop_after: 3s, lost_after: 1min, reconcile: keep_original}\n",
        "s.yaml",
    )
    assert s.component("A").disconnect == DisconnectSpec(3.0, True, 60.0, "keep_original")
    s = parse_system(BASE + "    disconnect: {stop_after: never}\n", "s.yaml")
    assert s.component("A").disconnect.stop_after_s is None
    assert system_from_json(s.to_json()) == s  # as plans carry it between robots


@pytest.mark.parametrize(
    ("block", "field", "says"),
    [
        ("{stop_after: -1s}", "components[0].disconnect.stop_after", "or never"),
        ("{lost_after: soon}", "components[0].disconnect.lost_after", "soon"),
        ("{replace: yes please}", "components[0].disconnect.replace", "true or false"),
        ("{reconcile: best}", "components[0].disconnect.reconcile", "keep_original"),
        ("{stop: 1s}", "components[0].disconnect.stop", "stop_after"),
        ("3s", "components[0].disconnect", "mapping"),
    ],
)
def test_a_wrong_disconnect_value_names_its_line_and_field(block: str, field: str, says: str):
    with pytest.raises(ConfigError) as e:
        parse_system(BASE + f"    disconnect: {block}\n", "s.yaml")
    text = str(e.value)
    assert "s.yaml:5" in text
    assert field in text
    assert says in text


def test_the_allocation_quorum_is_majority_unless_a_fleet_of_two_asks_for_any():
    assert parse_system(BASE, "s.yaml").allocation.quorum == "majority"
    s = parse_system("allocation: {quorum: any}\n" + BASE, "s.yaml")
    assert s.allocation.quorum == "any"
    assert system_from_json(s.to_json()) == s
    with pytest.raises(ConfigError) as e:
        parse_system("allocation: {quorum: most}\n" + BASE, "s.yaml")
    assert "s.yaml:1" in str(e.value)
    assert "allocation.quorum" in str(e.value)


def test_origins_travel_in_the_plan_until_the_component_is_back():
    back = DisconnectSpec(reconcile="keep_original")
    system = SystemDef("s", (comp("A", disconnect=back), comp("B")), allocation=TABLE_V)

    def plan(version: int, a: str, b: str, origins: tuple[tuple[str, str], ...] = ()) -> Plan:
        placements = (Placement("A", "A", a), Placement("B", "B", b))
        return Plan(1, version, system, placements, "robot-1", origins)

    alive = ClusterState(dict.fromkeys(("robot-1", "robot-3")))  # type: ignore[arg-type]
    old = plan(1, "robot-2", "robot-2")
    moved = with_origins(plan(2, "robot-3", "robot-3"), old, alive)
    assert moved.origins == (("A", "robot-2"),)  # B (keep_replacement) is not remembered
    assert plan_from_json(moved.to_json()) == moved  # it travels to every robot
    later = with_origins(plan(3, "robot-3", "robot-1"), moved, alive)
    assert later.origins == (("A", "robot-2"),)  # kept while A is elsewhere
    home = with_origins(plan(4, "robot-2", "robot-1"), later, alive)
    assert home.origins == ()  # A is back on robot-2
