"""The election rules with literal times: claims, grace periods, abdication, preemption,
conflicting claims, re-claims past a newer epoch, and priority at start (the priority window)."""

from __future__ import annotations

import math

import pytest

from sdrpeer.election import (
    Candidate,
    Elected,
    Election,
    ElectionConfig,
    ElectionError,
    ElectionEvent,
    ElectionState,
    LeaderChanged,
    Role,
    SteppedDown,
)
from sdrpeer.election.rules import TRANSITIONS, next_role

CONFIG = ElectionConfig(grace=1.0, startup_grace=0.0, rejoin_grace=0.0, priority_window=0.0)
"""The rules without the priority window (its own tests below give it one)."""
WINDOW = CONFIG.with_(startup_grace=1.5, priority_window=6.0)


def cand(
    *,
    alive: bool = True,
    eligible: bool = True,
    priority: int = 0,
    health: int = 3,
    state: ElectionState | None = None,
) -> Candidate:
    return Candidate(alive, eligible, priority, health, state)


def claim(epoch: int, name: str) -> ElectionState:
    return ElectionState(epoch, name, True)


def follows(epoch: int, name: str | None) -> ElectionState:
    return ElectionState(epoch, name, False)


def drain(e: Election) -> list[ElectionEvent]:
    out = []
    while (ev := e.next_event()) is not None:
        out.append(ev)
    return out


def test_the_only_robot_claims_epoch_one_at_once() -> None:
    e = Election("a", CONFIG, 0.0)
    e.update(0.0, {"a": cand()})
    assert e.is_leader
    assert e.role is Role.LEADER
    assert e.state() == claim(1, "a")
    assert drain(e) == [Elected(1, None, 0.0), LeaderChanged(1, "a", None, 0.0)]


def test_the_highest_ranked_claims_past_the_highest_epoch_seen() -> None:
    e = Election("b", CONFIG, 0.0)
    view = {
        "a": cand(priority=1, state=follows(7, "x")),
        "b": cand(priority=5),
        "x": cand(alive=False, state=claim(7, "x")),  # the dead allocator
    }
    e.update(0.0, view)
    assert e.state() == claim(8, "b")


def test_rank_is_priority_then_health_then_name() -> None:
    view = {"a": cand(priority=1, health=3), "b": cand(priority=2, health=0), "c": cand()}
    for name, leads in (("a", False), ("b", True), ("c", False)):
        e = Election(name, CONFIG, 0.0)
        e.update(0.0, view)
        assert e.is_leader is leads, name
    healthier = {"a": cand(health=2), "b": cand(health=1)}
    e = Election("a", CONFIG, 0.0)
    e.update(0.0, healthier)
    assert e.is_leader
    tie = {"a": cand(), "b": cand()}
    e = Election("b", CONFIG, 0.0)  # equal priority and health: the higher name
    e.update(0.0, tie)
    assert e.is_leader


def test_a_lower_robot_waits_a_grace_per_robot_above_then_claims() -> None:
    e = Election("c", CONFIG, 0.0)
    view = {"a": cand(priority=9), "b": cand(priority=5), "c": cand(priority=1)}
    e.update(10.0, view)
    assert e.role is Role.WAITING
    assert not e.is_leader
    assert e.next_timer() == 12.0  # two robots above: 2 * grace
    assert e.state() == follows(0, None)
    e.handle_timer(11.9)
    assert e.role is Role.WAITING
    e.handle_timer(12.0)  # nobody claimed: the bully whose higher peers do not answer
    assert e.state() == claim(1, "c")
    assert e.next_timer() == math.inf


def test_a_waiting_robot_follows_a_claim_that_arrives_within_grace() -> None:
    e = Election("b", CONFIG, 0.0)
    view = {"a": cand(priority=9), "b": cand(priority=1)}
    e.update(0.0, view)
    assert e.next_timer() == 1.0
    view["a"] = cand(priority=9, state=claim(1, "a"))
    e.update(0.3, view)
    assert e.role is Role.FOLLOWER
    assert e.leader == "a"
    assert e.epoch == 1
    assert e.next_timer() == math.inf
    assert e.state() == follows(1, "a")
    assert drain(e) == [LeaderChanged(1, "a", None, 0.3)]


def test_grace_shrinks_when_a_higher_robot_dies() -> None:
    e = Election("c", CONFIG, 0.0)
    view = {"a": cand(priority=9), "b": cand(priority=5), "c": cand(priority=1)}
    e.update(0.0, view)
    assert e.next_timer() == 2.0
    view["a"] = cand(priority=9, alive=False)
    e.update(0.5, view)
    assert e.next_timer() == 1.0


def test_startup_grace_holds_a_fresh_robot_back() -> None:
    e = Election("a", CONFIG.with_(startup_grace=1.5), 100.0)
    e.update(100.0, {"a": cand()})
    assert e.next_timer() == 101.5
    assert not e.is_leader
    e.update(100.5, {"a": cand(), "z": cand(priority=-1, state=claim(4, "z"))})
    assert e.leader == "z"
    assert e.next_timer() == math.inf


def test_a_robot_restarted_into_a_running_fleet_waits_longer_for_the_allocator() -> None:
    config = CONFIG.with_(startup_grace=1.5, rejoin_grace=6.0)
    fresh = Election("a", config, 100.0)
    fresh.update(100.0, {"a": cand()})
    assert fresh.next_timer() == 101.5
    back = Election("a", config, 100.0, known_epoch=7)  # it followed epoch 7 before
    back.update(100.0, {"a": cand()})
    assert back.next_timer() == 106.0
    back.handle_timer(101.5)
    assert not back.is_leader  # the allocator's claim may still be on its way
    back.update(104.0, {"a": cand(), "z": cand(priority=-1, state=claim(7, "z"))})
    assert back.leader == "z"
    assert not back.is_leader


def test_ineligible_or_dead_robots_neither_claim_nor_count_as_above() -> None:
    view = {"a": cand(priority=9, eligible=False), "b": cand(priority=5, alive=False), "c": cand()}
    e = Election("c", CONFIG, 0.0)
    e.update(0.0, view)
    assert e.is_leader
    e = Election("a", CONFIG, 0.0)
    e.update(0.0, view)
    assert e.role is Role.FOLLOWER
    assert e.next_timer() == math.inf


def test_an_allocator_that_becomes_ineligible_abdicates_and_the_next_claims() -> None:
    leader, other = Election("a", CONFIG, 0.0), Election("b", CONFIG, 0.0)
    view = {"a": cand(priority=9), "b": cand(priority=1)}
    leader.update(0.0, view)
    view["a"] = cand(priority=9, state=leader.state())
    other.update(0.1, view)
    assert other.leader == "a"
    drain(leader)
    view["a"] = cand(priority=9, eligible=False, state=leader.state())
    leader.update(1.0, view)
    assert leader.state() == follows(1, None)
    assert drain(leader) == [SteppedDown(1, "ineligible", 1.0), LeaderChanged(1, None, "a", 1.0)]
    view["a"] = cand(priority=9, eligible=False, state=leader.state())
    other.update(1.1, view)
    assert other.state() == claim(2, "b")  # the next one, with a higher epoch


def test_an_allocator_whose_claim_is_withdrawn_is_replaced_even_if_eligible() -> None:
    other = Election("b", CONFIG, 0.0)
    other.update(0.0, {"a": cand(priority=9, state=claim(3, "a")), "b": cand()})
    assert other.leader == "a"
    other.update(1.0, {"a": cand(priority=9, state=follows(3, None)), "b": cand()})
    assert other.role is Role.WAITING  # a still ranks above: one grace for it to claim again
    other.handle_timer(2.0)
    assert other.state() == claim(4, "b")


def test_a_leaving_allocator_abdicates_for_good() -> None:
    e = Election("a", CONFIG, 0.0)
    e.update(0.0, {"a": cand()})
    drain(e)
    e.leave(5.0)
    assert e.state() == follows(1, None)
    assert drain(e)[0] == SteppedDown(1, "left", 5.0)
    e.update(6.0, {"a": cand()})
    assert not e.is_leader
    assert e.role is Role.FOLLOWER


def test_a_dead_or_left_allocator_leaves_a_vacancy() -> None:
    e = Election("b", CONFIG, 0.0)
    e.update(0.0, {"a": cand(priority=9, state=claim(2, "a")), "b": cand()})
    assert e.leader == "a"
    e.update(3.0, {"a": cand(priority=9, alive=False, state=claim(2, "a")), "b": cand()})
    assert e.state() == claim(3, "b")


def test_no_preemption_a_returning_higher_robot_follows() -> None:
    back = Election("a", CONFIG, 50.0)
    view = {"a": cand(priority=9), "b": cand(priority=1, state=claim(4, "b"))}
    back.update(50.0, view)
    assert back.leader == "b"
    assert back.role is Role.FOLLOWER
    back.handle_timer(100.0)
    assert not back.is_leader


def test_preempt_a_returning_higher_robot_takes_the_role() -> None:
    back = Election("a", CONFIG.with_(preempt=True), 50.0)
    view = {"a": cand(priority=9), "b": cand(priority=1, state=claim(4, "b"))}
    back.update(50.0, view)
    assert back.state() == claim(5, "a")
    old = Election("b", CONFIG.with_(preempt=True), 0.0)
    old.update(0.0, {"b": cand(priority=1)})
    assert old.state() == claim(1, "b")
    drain(old)
    old.update(51.0, {"a": cand(priority=9, state=back.state()), "b": cand(priority=1)})
    assert old.state() == follows(5, "a")
    assert drain(old) == [SteppedDown(1, "outranked", 51.0), LeaderChanged(5, "a", "b", 51.0)]


def test_preempt_waits_for_robots_ranked_above_itself() -> None:
    e = Election("b", CONFIG.with_(preempt=True), 0.0)
    view = {
        "a": cand(priority=9),
        "b": cand(priority=5),
        "c": cand(priority=1, state=claim(2, "c")),
    }
    e.update(0.0, view)
    assert e.role is Role.WAITING
    assert e.next_timer() == 1.0
    view["a"] = cand(priority=9, state=claim(3, "a"))
    e.update(0.5, view)
    assert e.leader == "a"
    assert e.next_timer() == math.inf  # no longer waiting


def test_conflicting_claims_resolve_by_epoch_then_name() -> None:
    e = Election("z", CONFIG, 0.0)
    view = {
        "a": cand(priority=9, state=claim(4, "a")),
        "b": cand(priority=1, state=claim(5, "b")),
        "c": cand(state=claim(5, "c")),
        "z": cand(),
    }
    e.update(0.0, view)
    assert (e.epoch, e.leader) == (5, "c")
    view["c"] = cand(eligible=False, state=claim(5, "c"))  # an ineligible claim is not valid
    e.update(1.0, view)
    assert (e.epoch, e.leader) == (5, "b")


def test_a_claimer_steps_down_before_a_higher_claim_and_ignores_a_lower_one() -> None:
    e = Election("b", CONFIG, 0.0)
    e.update(0.0, {"b": cand()})
    assert e.state() == claim(1, "b")
    e.update(1.0, {"b": cand(), "a": cand(priority=9, state=claim(1, "a"))})
    assert e.is_leader  # same epoch, lower name: ours wins
    drain(e)
    e.update(2.0, {"b": cand(), "c": cand(state=claim(1, "c"))})
    assert e.state() == follows(1, "c")
    assert drain(e) == [SteppedDown(1, "outranked", 2.0), LeaderChanged(1, "c", "b", 2.0)]


def test_partition_heal_the_higher_epoch_wins() -> None:
    low, high = Election("a", CONFIG, 0.0), Election("b", CONFIG, 0.0)
    low.update(0.0, {"a": cand(priority=9)})
    high.update(0.0, {"b": cand(), "x": cand(alive=False, state=claim(6, "x"))})
    assert (low.epoch, high.epoch) == (1, 7)
    healed = {"a": cand(priority=9, state=low.state()), "b": cand(state=high.state())}
    low.update(1.0, healed)
    high.update(1.0, healed)
    assert low.state() == follows(7, "b")
    assert high.state() == claim(7, "b")


def test_an_allocator_whose_follower_knows_a_newer_epoch_claims_past_it() -> None:
    e = Election("a", CONFIG, 0.0)
    e.update(0.0, {"a": cand()})
    drain(e)
    view = {"a": cand(), "b": cand(state=follows(9, "x")), "x": cand(alive=False)}
    e.update(1.0, view)
    assert e.state() == claim(1, "a")  # b still follows x: not our business yet
    view["b"] = cand(state=follows(9, "a"))  # b follows us, fenced at 9
    e.update(2.0, view)
    assert e.state() == claim(10, "a")
    assert drain(e) == [Elected(10, 1, 2.0), LeaderChanged(10, "a", "a", 2.0)]


def test_an_allocator_holds_while_others_name_a_newer_one_it_cannot_see_yet() -> None:
    e = Election("a", CONFIG, 0.0)
    e.update(0.0, {"a": cand(priority=9)})
    view = {"a": cand(priority=9), "b": cand(state=follows(5, "c")), "c": cand(alive=False)}
    e.update(1.0, view)  # just healed: c is still dead here, its follower b already heard
    assert e.state() == claim(1, "a")
    view["c"] = cand(state=claim(5, "c"))
    e.update(1.5, view)
    assert e.state() == follows(5, "c")


def test_a_follower_publishes_the_highest_epoch_it_followed() -> None:
    e = Election("b", CONFIG, 0.0)
    view = {"a": cand(priority=9, state=claim(3, "a")), "b": cand(), "x": cand(state=claim(8, "x"))}
    e.update(0.0, view)
    assert e.state() == follows(8, "x")
    view["x"] = cand(alive=False, state=claim(8, "x"))
    e.update(1.0, view)
    assert (e.epoch, e.leader) == (3, "a")
    assert e.state() == follows(8, "a")  # its fence stays at 8: a must claim past it
    assert e.adopted_epoch == 8
    e.update(2.0, {**view, "z": cand(alive=False, state=claim(11, "z"))})
    assert e.state() == follows(8, "a")  # only heard of: not published
    assert e.max_epoch == 11


def test_known_epoch_survives_a_restart_and_own_stale_record_is_ignored() -> None:
    e = Election("a", CONFIG, 0.0, known_epoch=12)
    e.update(0.0, {"a": cand(state=claim(3, "a"))})  # our record from before the restart
    assert e.state() == claim(13, "a")


def test_a_robot_missing_from_its_own_view_never_claims() -> None:
    e = Election("a", CONFIG, 0.0)
    e.update(0.0, {"b": cand(alive=False)})
    assert e.role is Role.FOLLOWER
    assert e.state() == follows(0, None)


def test_the_role_table_rejects_illegal_moves() -> None:
    assert next_role(Role.WAITING, "claim") is Role.LEADER
    with pytest.raises(ElectionError, match="outranked"):
        next_role(Role.FOLLOWER, "outranked")
    assert {role for role, _ in TRANSITIONS} == set(Role)


def test_config_rejects_negative_graces() -> None:
    with pytest.raises(ValueError, match="grace"):
        ElectionConfig(grace=-1.0)


def test_at_boot_the_lower_ranked_waits_grace_after_the_startup_grace() -> None:
    config = ElectionConfig(grace=1.0, startup_grace=1.5)
    low = Election("z-low", config, 0.0)  # ranks below "a-high" only by priority
    view = {"z-low": cand(), "a-high": cand(priority=10)}
    low.update(0.0, view)
    assert low.next_timer() == 2.5  # 1.5 s startup grace, then 1 grace for the one above
    low.handle_timer(1.6)
    assert not low.is_leader  # "a-high", booted with it, has until 2.5 to claim
    low.update(1.7, {**view, "a-high": cand(priority=10, state=claim(1, "a-high"))})
    low.handle_timer(2.5)
    assert not low.is_leader
    assert low.leader == "a-high"


# -- priority at start: the priority window ---------------------------------------------------


def test_a_fresh_robot_of_higher_priority_takes_the_role_after_its_startup_grace() -> None:
    new = Election("b", WINDOW, 10.0)  # started after "a" claimed
    view = {"a": cand(priority=1, state=claim(1, "a")), "b": cand(priority=5)}
    new.update(10.0, view)
    assert new.leader == "a"
    assert new.role is Role.WAITING
    assert new.next_timer() == 11.5  # it hears the fleet first (startup grace)
    new.handle_timer(11.5)
    assert new.state() == claim(2, "b")
    old = Election("a", WINDOW, 0.0)
    old.update(0.0, {"a": cand(priority=1)})
    old.handle_timer(1.5)
    assert old.state() == claim(1, "a")
    drain(old)
    old.update(11.6, {"a": cand(priority=1), "b": cand(priority=5, state=new.state())})
    assert old.state() == follows(2, "b")
    assert drain(old) == [SteppedDown(1, "outranked", 11.6), LeaderChanged(2, "b", "a", 11.6)]


def test_a_lone_robot_claims_as_soon_as_without_the_window() -> None:
    for config in (WINDOW, WINDOW.with_(priority_window=0.0)):
        e = Election("a", config, 0.0)
        e.update(0.0, {"a": cand(priority=7)})
        assert e.next_timer() == 1.5
        e.handle_timer(1.5)
        assert e.state() == claim(1, "a")


def test_the_window_shuts_after_priority_window_seconds() -> None:
    late = Election("b", WINDOW, 0.0)
    view = {"a": cand(priority=1, state=claim(1, "a")), "b": cand(priority=5)}
    late.update(6.0, view)  # heard the allocator only when the window shut
    assert late.role is Role.FOLLOWER
    late.handle_timer(100.0)
    assert late.state() == follows(1, "a")


def test_a_countdown_that_ends_after_the_window_settles_without_claiming() -> None:
    config = WINDOW.with_(priority_window=3.0)
    e = Election("b", config, 0.0)
    view = {
        "a": cand(priority=1, state=claim(1, "a")),
        "b": cand(priority=5),
        "c": cand(priority=6),
        "d": cand(priority=7),
    }
    e.update(0.0, view)  # c and d rank above b: b's turn comes at 1.5 + 2 * 1.0 = 3.5
    assert e.next_timer() == 3.5
    e.handle_timer(3.5)
    assert e.role is Role.FOLLOWER
    assert e.state() == follows(1, "a")


def test_equal_priority_never_preempts_health_and_name_do_not_count() -> None:
    e = Election("z", WINDOW, 0.0)
    view = {"a": cand(priority=3, health=0, state=claim(1, "a")), "z": cand(priority=3, health=3)}
    e.update(0.0, view)
    e.handle_timer(2.0)
    assert e.role is Role.FOLLOWER
    assert e.state() == follows(1, "a")


def test_a_robot_restarted_into_its_fleet_does_not_preempt() -> None:
    back = Election("b", WINDOW, 50.0, known_epoch=4)
    view = {"a": cand(priority=1, state=claim(4, "a")), "b": cand(priority=9)}
    back.update(50.0, view)
    back.handle_timer(60.0)
    assert back.state() == follows(4, "a")


def test_the_deployed_systems_preempt_lets_a_higher_robot_take_the_role_at_any_time() -> None:
    e = Election("b", CONFIG, 0.0)
    view = {"a": cand(priority=1, state=claim(3, "a")), "b": cand(priority=5)}
    e.update(100.0, view)
    assert e.state() == follows(3, "a")
    e.update(101.0, view, preempt=True)
    assert e.state() == claim(4, "b")
