"""The lifecycle table: every state x event pair, legal and illegal."""

from __future__ import annotations

import itertools

import pytest

from sdrpeer.errors import SdrpeerError
from sdrpeer.sdk import LifecycleError, LifecycleState
from sdrpeer.sdk.lifecycle import EVENTS, next_state

S = LifecycleState

LEGAL = {
    (S.CREATED, "initialize"): S.INACTIVE,
    (S.CREATED, "error"): S.ERROR,
    (S.CREATED, "finalize"): S.FINALIZED,
    (S.INACTIVE, "activate"): S.ACTIVE,
    (S.INACTIVE, "error"): S.ERROR,
    (S.INACTIVE, "finalize"): S.FINALIZED,
    (S.ACTIVE, "deactivate"): S.INACTIVE,
    (S.ACTIVE, "error"): S.ERROR,
    (S.ERROR, "reset"): S.INACTIVE,
    (S.ERROR, "finalize"): S.FINALIZED,
}

ALL_PAIRS = list(itertools.product(list(S), EVENTS))


def test_state_values_are_the_protocol_names() -> None:
    assert [s.value for s in S] == ["CREATED", "INACTIVE", "ACTIVE", "ERROR", "FINALIZED"]
    assert S("ERROR") is S.ERROR
    assert f"{S.ACTIVE}" == "ACTIVE"


@pytest.mark.parametrize(("state", "event"), ALL_PAIRS)
def test_every_pair(state: LifecycleState, event: str) -> None:
    if (state, event) in LEGAL:
        assert next_state(state, event) is LEGAL[(state, event)]
    else:
        with pytest.raises(LifecycleError) as info:
            next_state(state, event)
        assert str(info.value).startswith(f"cannot {event}: component is {state.value}")
        assert info.value.event == event
        assert info.value.state == state.value
        assert isinstance(info.value, SdrpeerError)


def test_the_table_has_exactly_the_legal_pairs() -> None:
    legal = {p for p in ALL_PAIRS if _legal(*p)}
    assert legal == set(LEGAL)


def _legal(state: LifecycleState, event: str) -> bool:
    try:
        next_state(state, event)
    except LifecycleError:
        return False
    return True


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
