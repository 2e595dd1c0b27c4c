"""The pure reconciler and restart backoff: tables of (desired, observed) -> actions."""

from __future__ import annotations

from typing import Any

import pytest

from sdrpeer.runtime.backoff import RestartConfig, RestartPolicy, backoff_delay
from sdrpeer.runtime.reconciler import Action, Observed, Reconciler
from sdrpeer.runtime.spec import ConnectionSpec, InstanceSpec
from sdrpeer.vocabulary import InstanceRole, LifecycleState, ProcessState

CAM_TO_VIEW = ConnectionSpec("c1", "image", "View", "image")


def spec(name: str, *conns: ConnectionSpec, **kw: Any) -> InstanceSpec:
    return InstanceSpec(name, name, "python", f"pkg.mod:{name}", connections=conns, **kw)


CAM = spec("Cam", CAM_TO_VIEW)
VIEW = spec("View")
ADDR = "unix:///run/view.sock"


STATES = {s.value: s for s in (*LifecycleState, *ProcessState)}


def obs(
    status: str, s: InstanceSpec | None = None, addr: str | None = None, **conns: Any
) -> Observed:
    return Observed(STATES[status], s, addr, conns)


def kinds(actions: list[Action]) -> list[tuple[str, str]]:
    return [(a.kind, a.instance) for a in actions]


CASES: list[tuple[str, dict[str, InstanceSpec], dict[str, Observed], list[tuple[str, str]]]] = [
    ("nothing to do", {}, {}, []),
    ("start what is missing", {"View": VIEW}, {}, [("start", "View")]),
    ("wait while starting", {"View": VIEW}, {"View": obs("STARTING", VIEW)}, []),
    (
        "activate a lone instance",
        {"View": VIEW},
        {"View": obs("INACTIVE", VIEW)},
        [("activate", "View")],
    ),
    ("active is converged", {"View": VIEW}, {"View": obs("ACTIVE", VIEW)}, []),
    ("stop what is not desired", {}, {"View": obs("ACTIVE", VIEW)}, [("stop", "View")]),
    ("stopped and undesired: nothing", {}, {"View": obs("STOPPED", VIEW)}, []),
    ("stopping: wait", {}, {"View": obs("STOPPING", VIEW)}, []),
    ("undesired FAILED: stop (forget)", {}, {"View": obs("FAILED", VIEW)}, [("stop", "View")]),
    ("FAILED stays FAILED", {"View": VIEW}, {"View": obs("FAILED", VIEW)}, []),
    (
        "FAILED with a new spec: start",
        {"View": spec("View", params=(("x", 1),))},
        {"View": obs("FAILED", VIEW)},
        [("start", "View")],
    ),
    (
        "process fields changed: stop first",
        {"View": spec("View", params=(("x", 1),))},
        {"View": obs("ACTIVE", VIEW)},
        [("stop", "View")],
    ),
    ("ERROR: left alone", {"View": VIEW}, {"View": obs("ERROR", VIEW)}, []),
    (
        "desired inactive: deactivate",
        {"View": spec("View", desired=LifecycleState.INACTIVE)},
        {"View": obs("ACTIVE", VIEW)},
        [("deactivate", "View")],
    ),
    (
        "a standby is kept INACTIVE",
        {"View": spec("View", role="standby")},
        {"View": obs("INACTIVE", VIEW)},
        [],
    ),
    (
        "both start together",
        {"Cam": CAM, "View": VIEW},
        {},
        [("start", "Cam"), ("start", "View")],
    ),
    (
        "sender waits for the receiver's address; receiver activates",
        {"Cam": CAM, "View": VIEW},
        {"Cam": obs("INACTIVE", CAM), "View": obs("STARTING", VIEW)},
        [],
    ),
    (
        "connect once the receiver's address is known",
        {"Cam": CAM, "View": VIEW},
        {"Cam": obs("INACTIVE", CAM), "View": obs("INACTIVE", VIEW, ADDR)},
        [("connect", "Cam"), ("activate", "View")],
    ),
    (
        "connected sender waits for its receiver to be ACTIVE",
        {"Cam": CAM, "View": VIEW},
        {"Cam": obs("INACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR)), "View": obs("INACTIVE", VIEW, ADDR)},
        [("activate", "View")],
    ),
    (
        "receiver ACTIVE: sender activates",
        {"Cam": CAM, "View": VIEW},
        {"Cam": obs("INACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR)), "View": obs("ACTIVE", VIEW, ADDR)},
        [("activate", "Cam")],
    ),
    (
        "receiver restarted elsewhere: repoint",
        {"Cam": CAM, "View": VIEW},
        {
            "Cam": obs("ACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR)),
            "View": obs("INACTIVE", VIEW, "unix:///run/new.sock"),
        },
        [("repoint", "Cam"), ("activate", "View")],
    ),
    (
        "remote receiver moving (address unknown): the connection stays as made",
        {"Cam": spec("Cam", ConnectionSpec("c1", "image", "View", "image", pending=True))},
        {"Cam": obs("ACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR))},
        [],
    ),
    (
        "remote receiver's new address known: repoint",
        {"Cam": spec("Cam", ConnectionSpec("c1", "image", "View", "image", to_addr="tcp://h:9"))},
        {"Cam": obs("ACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR))},
        [("repoint", "Cam")],
    ),
    (
        "pending connection not made yet: none made (derive decides whether it activates)",
        {"Cam": spec("Cam", ConnectionSpec("c1", "image", "View", "image", pending=True))},
        {"Cam": obs("INACTIVE", CAM)},
        [("activate", "Cam")],
    ),
    (
        "receiver is another instance now (a standby promoted): repoint, not reconnect",
        {"Cam": spec("Cam", ConnectionSpec("c1", "image", "View-s1", "image")), "View-s1": VIEW},
        {
            "Cam": obs("ACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR)),
            "View-s1": obs("ACTIVE", VIEW, "unix:///run/standby.sock"),
        },
        [("repoint", "Cam")],
    ),
    (
        "connection no longer desired: disconnect",
        {"Cam": spec("Cam"), "View": VIEW},
        {"Cam": obs("ACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR)), "View": obs("ACTIVE", VIEW, ADDR)},
        [("disconnect", "Cam")],
    ),
    (
        "connection's policy changed: disconnect (then connect)",
        {
            "Cam": spec("Cam", ConnectionSpec("c1", "image", "View", "image", (("buffer", 2),))),
            "View": VIEW,
        },
        {"Cam": obs("ACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR)), "View": obs("ACTIVE", VIEW, ADDR)},
        [("disconnect", "Cam")],
    ),
    (
        "explicit to_addr: connect without a local receiver",
        {"Cam": spec("Cam", ConnectionSpec("c1", "image", "Far", "image", to_addr="tcp://h:1"))},
        {"Cam": obs("INACTIVE", CAM)},
        [("connect", "Cam")],
    ),
    (
        "receivers go down after their senders",
        {
            "Cam": spec("Cam", CAM_TO_VIEW, desired=LifecycleState.INACTIVE),
            "View": spec("View", desired=LifecycleState.INACTIVE),
        },
        {"Cam": obs("ACTIVE", CAM, c1=(CAM_TO_VIEW, ADDR)), "View": obs("ACTIVE", VIEW, ADDR)},
        [("deactivate", "Cam")],
    ),
]


@pytest.mark.parametrize(
    ("desired", "observed", "expected"), [c[1:] for c in CASES], ids=[c[0] for c in CASES]
)
def test_plan(desired, observed, expected):
    assert kinds(Reconciler().plan(0.0, desired, observed)) == expected


def test_connect_action_carries_the_resolved_address():
    desired = {"Cam": CAM, "View": VIEW}
    observed = {"Cam": obs("INACTIVE", CAM), "View": obs("INACTIVE", VIEW, ADDR)}
    connect = Reconciler().plan(0.0, desired, observed)[0]
    assert (connect.conn, connect.to) == (CAM_TO_VIEW, ADDR)


def test_a_cycle_does_not_deadlock_activation():
    a = spec("A", ConnectionSpec("ab", "o", "B", "i"))
    b = spec("B", ConnectionSpec("ba", "o", "A", "i"))
    observed = {
        "A": obs("INACTIVE", a, "unix:///a", ab=(a.connections[0], "unix:///b")),
        "B": obs("INACTIVE", b, "unix:///b", ba=(b.connections[0], "unix:///a")),
    }
    assert kinds(Reconciler().plan(0.0, {"A": a, "B": b}, observed)) == [
        ("activate", "A"),
        ("activate", "B"),
    ]


def test_no_second_action_while_one_is_in_flight_until_done_or_timeout():
    r = Reconciler(action_timeout=10.0)
    desired, observed = {"View": VIEW}, {"View": obs("INACTIVE", VIEW)}
    assert kinds(r.plan(0.0, desired, observed)) == [("activate", "View")]
    assert r.plan(1.0, desired, observed) == []
    assert r.plan(9.9, desired, observed) == []
    assert kinds(r.plan(10.0, desired, observed)) == [("activate", "View")]  # timed out
    r.done("View")
    assert kinds(r.plan(10.1, desired, observed)) == [("activate", "View")]


@pytest.mark.parametrize(
    ("failures", "delay"), [(1, 0.1), (2, 0.2), (3, 0.4), (6, 3.2), (7, 5.0), (20, 5.0)]
)
def test_backoff_delay(failures, delay):
    assert backoff_delay(RestartConfig(), failures) == pytest.approx(delay)


def test_restart_policy_resets_after_a_stable_run_and_gives_up():
    p = RestartPolicy(RestartConfig(max_fast_failures=3, stable_after=30.0))
    assert p.on_exit(started=0.0, now=1.0) == pytest.approx(0.1)
    assert p.on_exit(started=1.1, now=2.0) == pytest.approx(0.2)
    assert p.on_exit(started=2.2, now=40.0) == pytest.approx(0.1)  # ran 37.8 s: stable
    assert p.on_exit(started=40.1, now=41.0) == pytest.approx(0.2)
    assert p.on_exit(started=41.2, now=42.0) is None  # third fast failure in a row
    p.reset()
    assert p.on_exit(started=50.0, now=51.0) == pytest.approx(0.1)


# ------------------------------------------------------------------ paced starts


def test_standbys_starts_are_paced_and_wait_for_the_actives() -> None:
    # Twenty hosts spawned at once starved ten agents on two cores (issue 30): standbys start at
    # most max_starting at a time, and only once no would-be active waits to start; actives
    # start at once (a recovery launching five cold components needs all five).
    standbys = {f"S{i}": spec(f"S{i}", role=InstanceRole.STANDBY) for i in range(3)}
    actives = {f"A{i}": spec(f"A{i}") for i in range(3)}
    desired = {**standbys, **actives}
    r = Reconciler(max_starting=2)
    assert kinds(r.plan(0.0, desired, {})) == [("start", "A0"), ("start", "A1"), ("start", "A2")]
    assert r.plan(0.1, desired, {}) == []  # three starts in flight: no room for a standby
    for a in actives:
        r.done(a)
    starting = {a: obs("STARTING", s) for a, s in actives.items()}
    starting["A1"] = obs("CREATED", actives["A1"])
    assert r.plan(0.2, desired, starting) == []  # spawned, not initialized yet: no room
    starting["A0"] = obs("INACTIVE", actives["A0"])
    starting["A1"] = obs("INACTIVE", actives["A1"])
    assert kinds(r.plan(0.3, desired, starting)) == [
        ("activate", "A0"),
        ("activate", "A1"),
        ("start", "S0"),
    ]


def test_without_a_limit_every_start_goes_at_once() -> None:
    desired = {f"S{i}": spec(f"S{i}") for i in range(5)}
    assert len(Reconciler().plan(0.0, desired, {})) == 5
