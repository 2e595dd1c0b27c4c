"""Plan -> instance specs for one robot, and the plan store's fencing and persistence."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from sdrpeer.deploy.derive import (
    Remote,
    handover_waits,
    reachable,
    specs_for_robot,
    superseded,
)
from sdrpeer.deploy.placer import relaxed_for_recovery
from sdrpeer.deploy.planstore import PlanStore
from sdrpeer.plan import Placement, Plan, plan_from_json
from sdrpeer.system.loader import load_system
from sdrpeer.system.model import ComponentDef, ConnectionDef, StandbySpec, StreamsDef, SystemDef
from sdrpeer.vocabulary import InstanceRole, LifecycleState


def _system(cycle: bool = False) -> SystemDef:
    comps = tuple(
        ComponentDef(name=n, launcher="python", target=f"components.x:{n}", params=(("k", 1),))
        for n in ("Cam", "Det", "Ctl")
    )
    conns = [
        ConnectionDef("Cam", "image", "Det", "image", (("buffer", 4),)),
        ConnectionDef("Det", "alarm", "Ctl", "alarm"),
    ]
    if cycle:
        conns.append(ConnectionDef("Ctl", "odom", "Det", "odom"))
    return SystemDef(name="s", components=comps, connections=tuple(conns))


def _plan(system: SystemDef, where: dict[str, str], **kw: object) -> Plan:
    placements = [Placement(c, c, r) for c, r in where.items()]
    placements.append(Placement("Cam", "Cam-s1", "r2", InstanceRole.STANDBY, "hot"))
    placements.append(Placement("Det", "Det-s1", "r2", InstanceRole.STANDBY, "cold"))
    return Plan(epoch=1, version=1, system=system, placements=tuple(placements), allocator="r1")


def test_local_connections_resolve_by_the_reconciler() -> None:
    plan = _plan(_system(), {"Cam": "r1", "Det": "r1", "Ctl": "r1"})
    specs = {s.name: s for s in specs_for_robot(plan, "r1", {})}
    assert sorted(specs) == ["Cam", "Ctl", "Det"]
    cam = specs["Cam"]
    assert cam.desired == LifecycleState.ACTIVE
    assert cam.params == (("k", 1),)
    (conn,) = cam.connections
    assert (conn.id, conn.to_instance, conn.in_port, conn.to_addr) == (
        "Cam.image->Det.image",
        "Det",
        "image",
        None,
    )
    assert conn.policy == (("buffer", 4),)
    assert specs["Ctl"].connections == ()


def test_standbys_hot_started_cold_not_and_standbys_do_not_send() -> None:
    plan = _plan(_system(), {"Cam": "r1", "Det": "r1", "Ctl": "r1"})
    specs = specs_for_robot(plan, "r2", {})
    assert [(s.name, s.role, s.connections) for s in specs] == [("Cam-s1", "standby", ())]


def test_a_move_between_alive_robots_is_break_before_make() -> None:
    """Ctl moved from r2 to r1: while r2 still runs its Ctl ACTIVE as the active, r1's waits."""
    plan = _plan(_system(), {"Cam": "r1", "Det": "r1", "Ctl": "r1"})
    old = {"Ctl": Remote("r2", LifecycleState.ACTIVE, "tcp://127.0.0.1:4001", "Ctl", "active")}
    assert handover_waits(plan, "r1", old) == {"Ctl"}
    specs = {s.name: s for s in specs_for_robot(plan, "r1", old, hold={"Ctl"})}
    assert specs["Ctl"].desired == LifecycleState.INACTIVE
    assert specs["Cam"].desired == specs["Det"].desired == LifecycleState.ACTIVE
    assert handover_waits(plan, "r1", old, active_here={"Ctl"}) == set()  # running: never held
    stood_down = {
        "Ctl": Remote("r2", LifecycleState.INACTIVE, "tcp://127.0.0.1:4001", "Ctl", "standby")
    }
    assert handover_waits(plan, "r1", stood_down) == set()
    a_standby = {
        "Ctl-s1": Remote("r2", LifecycleState.ACTIVE, None, "Ctl", "standby")
    }  # not the active
    assert handover_waits(plan, "r1", a_standby) == set()
    assert handover_waits(plan, "r2", old) == set()  # r2 places no active


def test_the_old_side_of_a_heal_yields_to_a_newer_plans_running_copy() -> None:
    """r1 still runs Ctl ACTIVE under its old plan; r2, holding a newer plan, runs Ctl ACTIVE as
    its active: r1 stands its copy down (held INACTIVE although it runs) before it has the plan."""
    plan = _plan(_system(), {"Cam": "r1", "Det": "r1", "Ctl": "r1"})
    new = {"Ctl": Remote("r2", LifecycleState.ACTIVE, "tcp://127.0.0.1:4001", "Ctl", "active")}
    assert superseded(plan, "r1", new, newer={"r2"}) == {"Ctl"}
    specs = {s.name: s for s in specs_for_robot(plan, "r1", new, active_here={"Ctl"}, hold={"Ctl"})}
    assert specs["Ctl"].desired == LifecycleState.INACTIVE
    assert specs["Cam"].desired == LifecycleState.ACTIVE
    assert superseded(plan, "r1", new, newer=set()) == set()  # r2's plan is not newer: r1 keeps it
    held = {"Ctl": Remote("r2", LifecycleState.INACTIVE, "tcp://127.0.0.1:4001", "Ctl", "active")}
    assert superseded(plan, "r1", held, newer={"r2"}) == set()  # r2's copy waits: a handover
    spare = {"Ctl-s1": Remote("r2", LifecycleState.ACTIVE, None, "Ctl", "standby")}
    assert superseded(plan, "r1", spare, newer={"r2"}) == set()  # a standby is not the active
    assert superseded(plan, "r2", new, newer={"r2"}) == set()  # never yields to itself


def test_the_systems_streams_switch_reaches_every_connection_unless_it_says_otherwise() -> None:
    system = replace(
        _system(),
        streams=StreamsDef(encrypt=False),
        connections=(
            ConnectionDef("Cam", "image", "Det", "image"),
            ConnectionDef("Det", "alarm", "Ctl", "alarm", (("encrypt", True),)),
        ),
    )
    plan = _plan(system, {"Cam": "r1", "Det": "r1", "Ctl": "r1"})
    specs = {s.name: s for s in specs_for_robot(plan, "r1", {})}
    assert specs["Cam"].connections[0].policy == (("encrypt", False),)
    assert specs["Det"].connections[0].policy == (("encrypt", True),)  # its own word wins
    default = _plan(_system(), {"Cam": "r1", "Det": "r1", "Ctl": "r1"})
    (cam,) = [s for s in specs_for_robot(default, "r1", {}) if s.name == "Cam"]
    assert cam.connections[0].policy == (("buffer", 4),)  # encrypted: the default, unsaid


def test_remote_receiver_waits_for_address_then_for_active() -> None:
    plan = _plan(_system(), {"Cam": "r1", "Det": "r2", "Ctl": "r2"})
    (cam,) = specs_for_robot(plan, "r1", {})
    assert [(c.to_instance, c.to_addr, c.pending) for c in cam.connections] == [("Det", None, True)]
    assert cam.desired == LifecycleState.INACTIVE
    started = {"Det": Remote("r2", LifecycleState.INACTIVE, "tcp://127.0.0.1:4000")}
    (cam,) = specs_for_robot(plan, "r1", started)
    assert cam.connections[0].to_addr == "tcp://127.0.0.1:4000"
    assert cam.desired == LifecycleState.INACTIVE  # receiver not ACTIVE yet
    active = {"Det": Remote("r2", LifecycleState.ACTIVE, "tcp://127.0.0.1:4000")}
    (cam,) = specs_for_robot(plan, "r1", active)
    assert cam.desired == LifecycleState.ACTIVE


def test_running_sender_is_not_held_back_when_receiver_moves() -> None:
    plan = _plan(_system(), {"Cam": "r1", "Det": "r3", "Ctl": "r3"})
    stale = {"Det": Remote("r2", LifecycleState.ACTIVE, "tcp://127.0.0.1:4000")}  # old robot
    (cam,) = specs_for_robot(plan, "r1", stale, active_here={"Cam"})
    assert [c.pending for c in cam.connections] == [True]  # kept as made until Det is known
    assert cam.desired == LifecycleState.ACTIVE


def test_cycle_across_robots_does_not_deadlock() -> None:
    system = _system(cycle=True)
    assert "Det" in reachable(system)["Det"]
    plan = _plan(system, {"Cam": "r1", "Det": "r1", "Ctl": "r2"})
    remote = {"Ctl": Remote("r2", LifecycleState.INACTIVE, "tcp://127.0.0.1:4001")}
    specs = {s.name: s for s in specs_for_robot(plan, "r1", remote)}
    assert specs["Det"].desired == LifecycleState.ACTIVE


def test_undeployed_plan_hosts_nothing() -> None:
    assert specs_for_robot(Plan(2, 1, None), "r1", {}) == []


def test_plan_json_round_trip() -> None:
    system = SystemDef(
        name="s",
        components=(
            ComponentDef("A", "exec", ("prog", "--x"), (("list", (1, 2)),), standby=StandbySpec(1)),
        ),
    )
    plan = Plan(3, 4, system, (Placement("A", "A", "r1"),), "r1")
    assert plan_from_json(plan.to_json()) == plan


def test_store_fences_older_allocators_and_persists(tmp_path: Path) -> None:
    system = _system()
    store = PlanStore(tmp_path / "plan.json")
    assert store.offer(Plan(2, 1, system, (), "a"))
    assert not store.offer(Plan(2, 1, system, (), "a"))  # not newer
    assert not store.offer(Plan(1, 9, system, (), "old"))  # stale allocator
    assert store.offer(Plan(2, 1, system, (), "b"))  # same epoch, higher name: wins
    assert not store.offer(Plan(2, 5, system, (), "a"))  # "a" lost epoch 2 to "b"
    store.see_claim(5, "c")
    assert not store.offer(Plan(4, 1, system, (), "z"))  # an allocator of epoch 5 exists
    assert store.offer(Plan(5, 1, None, (), "c"))
    assert store.refused_stale == 4
    info = store.info()
    assert info is not None
    assert (info.epoch, info.version, info.allocator) == (5, 1, "c")
    store.save()  # the shell saves what the core took
    again = PlanStore(tmp_path / "plan.json")
    assert again.plan == Plan(5, 1, None, (), "c")
    assert again.highest_epoch == 5
    assert again.info() == info


def test_store_ignores_a_corrupt_file(tmp_path: Path) -> None:
    (tmp_path / "plan.json").write_text("{not json")
    assert PlanStore(tmp_path / "plan.json").plan is None


def test_recovery_relaxes_only_the_free_memory_threshold() -> None:
    paper = load_system(Path(__file__).parent.parent / "examples/paper/system.yaml")
    t = paper.allocation.thresholds
    assert t.mem_free_above_bytes == 500_000_000
    relaxed = relaxed_for_recovery(paper)
    assert relaxed.allocation.thresholds.mem_free_above_bytes == 250_000_000  # shortage clears
    assert relaxed.components == paper.components
    bare = relaxed_for_recovery(_system())
    assert bare.allocation.thresholds.mem_free_above_bytes is None
