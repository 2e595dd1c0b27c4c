"""The lifecycle table: every state x event pair, legal and illegal."""

from __future__ import annotations

import itertools

import pytest

from sdrpeer.errors import SdrpeerError
from sdrpeer.sdk import LifecycleError, LifecycleState
from sdrpeer.sdk.lifecycle import EVENTS, next_state

S = LifecycleState

ALL_PAIRS = list(itertools.product(list(S), EVENTS))

# Transitions the specification names (OpenRTM-aist's RTC lifecycle, and the rules at the top of
# sdrpeer/sdk/lifecycle.py), written from the spec, not copied from the table.
SPEC_MOVES = [
    (S.CREATED, "initialize", S.INACTIVE),  # OpenRTM: initialize() enters Alive, Inactive
    (S.INACTIVE, "activate", S.ACTIVE),  # activate_component: on_activated
    (S.ACTIVE, "deactivate", S.INACTIVE),  # deactivate_component: on_deactivated
    (S.ACTIVE, "error", S.ERROR),  # a failing on_execute: on_aborting, then Error
    (S.ERROR, "reset", S.INACTIVE),  # reset_component: on_reset, back to Inactive
    (S.INACTIVE, "finalize", S.FINALIZED),  # exit(): on_finalize
    (S.INACTIVE, "error", S.ERROR),  # rule 3: on_activated or a params callback failed
    (S.CREATED, "error", S.ERROR),  # rule 3: on_initialize failed
    (S.ERROR, "finalize", S.FINALIZED),  # rule 4
]
SPEC_REFUSALS = [
    (S.CREATED, "activate"),  # OpenRTM: only an initialized (Inactive) component activates
    (S.INACTIVE, "reset"),  # reset_component applies to a component in Error only
    (S.ACTIVE, "reset"),
    (S.ERROR, "activate"),  # rule 4: ERROR is left by reset or finalize only
    (S.ERROR, "deactivate"),
    (S.ACTIVE, "finalize"),  # rule 5: deactivate first
    (S.ACTIVE, "activate"),  # activate_component on an active component: PRECONDITION_NOT_MET
    (S.INACTIVE, "initialize"),  # initialize() once
]


def _legal(state: LifecycleState, event: str) -> bool:
    try:
        next_state(state, event)
    except LifecycleError:
        return False
    return True


def test_state_values_are_the_protocol_names() -> None:
    assert [s.value for s in S] == ["CREATED", "INACTIVE", "ACTIVE", "ERROR", "FINALIZED"]
    assert S("ERROR") is S.ERROR
    assert f"{S.ACTIVE}" == "ACTIVE"


@pytest.mark.parametrize(("state", "event", "after"), SPEC_MOVES)
def test_the_specs_transitions(state: LifecycleState, event: str, after: LifecycleState) -> None:
    assert next_state(state, event) is after


@pytest.mark.parametrize(("state", "event"), SPEC_REFUSALS)
def test_the_specs_refusals(state: LifecycleState, event: str) -> None:
    assert not _legal(state, event)


@pytest.mark.parametrize(("state", "event"), [p for p in ALL_PAIRS if not _legal(*p)])
def test_every_refusal_says_which_event_in_which_state(state: LifecycleState, event: str) -> None:
    with pytest.raises(LifecycleError) as info:
        next_state(state, event)
    assert str(info.value).startswith(f"cannot {event}: component is {state.value}")
    assert info.value.event == event
    assert info.value.state == state.value
    assert isinstance(info.value, SdrpeerError)


def test_an_event_has_one_target_whatever_the_state_and_always_moves() -> None:
    """Each event names where it goes (initialize -> INACTIVE, ..., finalize -> FINALIZED); no
    legal event leaves the state as it was."""
    targets: dict[str, set[LifecycleState]] = {e: set() for e in EVENTS}
    for state, event in ALL_PAIRS:
        if _legal(state, event):
            after = next_state(state, event)
            targets[event].add(after)
            assert after is not state, (state, event)
    assert targets == {
        "initialize": {S.INACTIVE},
        "activate": {S.ACTIVE},
        "deactivate": {S.INACTIVE},
        "error": {S.ERROR},
        "reset": {S.INACTIVE},
        "finalize": {S.FINALIZED},
    }


def test_every_state_is_reachable_and_every_live_state_can_still_finalize() -> None:
    def reachable(start: LifecycleState) -> set[LifecycleState]:
        seen, todo = {start}, [start]
        while todo:  # bounded: at most one visit per state
            state = todo.pop()
            for event in EVENTS:
                if _legal(state, event) and (after := next_state(state, event)) not in seen:
                    seen.add(after)
                    todo.append(after)
        return seen

    assert reachable(S.CREATED) == set(S)
    for state in S:
        assert S.FINALIZED in reachable(state), state  # nothing gets stuck alive


def test_active_is_entered_only_by_activate_from_inactive() -> None:
    into_active = {
        (state, event)
        for state, event in ALL_PAIRS
        if _legal(state, event) and next_state(state, event) is S.ACTIVE
    }
    assert into_active == {(S.INACTIVE, "activate")}


def test_error_is_reached_from_every_live_state_and_left_only_by_reset_or_finalize() -> None:
    assert {s for s in S if _legal(s, "error")} == {S.CREATED, S.INACTIVE, S.ACTIVE}
    assert {e for e in EVENTS if _legal(S.ERROR, e)} == {"reset", "finalize"}


@pytest.mark.parametrize(
    ("state", "event", "message"),
    [
        (S.ERROR, "activate", "cannot activate: component is ERROR (reset it first)"),
        (S.ACTIVE, "finalize", "cannot finalize: component is ACTIVE (deactivate it first)"),
        (S.CREATED, "activate", "cannot activate: component is CREATED (initialize it first)"),
        (S.FINALIZED, "reset", "cannot reset: component is FINALIZED (it is finalized)"),
        (S.ACTIVE, "activate", "cannot activate: component is ACTIVE (already active)"),
    ],
)
def test_messages_say_what_to_do(state: LifecycleState, event: str, message: str) -> None:
    with pytest.raises(LifecycleError) as info:
        next_state(state, event)
    assert str(info.value) == message


def test_unknown_event_is_a_bug_not_a_lifecycle_error() -> None:
    with pytest.raises(ValueError, match="unknown lifecycle event 'start'"):
        next_state(S.INACTIVE, "start")


def test_finalized_is_terminal() -> None:
    for event in EVENTS:
        with pytest.raises(LifecycleError):
            next_state(S.FINALIZED, event)
