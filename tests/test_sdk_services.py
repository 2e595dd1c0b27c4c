"""Service ports in the SDK: interfaces and their ids, declarations checked at class creation,
and a provider's answers (its runtime is pure: it is handed a reply callback)."""

from __future__ import annotations

from dataclasses import dataclass
from hashlib import blake2b
from typing import Any

import pytest

from components.planner import PLANNER, Goal, PathPlanner
from sdrpeer.sdk import (
    Component,
    ComponentError,
    Interface,
    ServiceCallError,
    ServiceConsumer,
    ServiceError,
    ServiceProvider,
    ServiceTimeout,
    ServiceUnavailable,
    message,
)
from tests.components_fixture import ECHO, EchoCaller, EchoService


@message("test/Num")
@dataclass(frozen=True, slots=True)
class Num:
    n: int


@pytest.mark.parametrize(
    ("interface", "layout"),
    [
        (Interface.of("a/B", "x"), "a/B(x:any>any)"),
        (Interface.of("a/B", "y", "x"), "a/B(x:any>any;y:any>any)"),
        (Interface.of("a/B", "x", types={"x": (Num, None)}), "a/B(x:test/Num#8cc11237>any)"),
    ],
)
def test_interface_id_is_a_digest_of_its_layout(interface: Interface, layout: str) -> None:
    digest = blake2b(layout.encode(), digest_size=4).hexdigest()
    assert interface.id == f"a/B#{digest}"


def test_interfaces_that_differ_have_different_ids() -> None:
    ids = {
        Interface.of("a/B", "x").id,
        Interface.of("a/B", "x", "y").id,
        Interface.of("a/C", "x").id,
        Interface.of("a/B", "x", types={"x": (Num, None)}).id,
        Interface.of("a/B", "x", types={"x": (None, Num)}).id,
    }
    assert len(ids) == 5
    assert Interface.of("a/B", "x", "y").id == Interface.of("a/B", "y", "x").id


@pytest.mark.parametrize(
    ("args", "kwargs", "error"),
    [
        (("bad name", "x"), {}, "no spaces or '#'"),
        (("a/B",), {}, "no methods"),
        (("a/B", "_x"), {}, "not a public identifier"),
        (("a/B", "x", "x"), {}, "named twice"),
        (("a/B", "x"), {"types": {"y": (None, None)}}, "unknown method 'y'"),
    ],
)
def test_bad_interfaces_are_refused(args: tuple[str, ...], kwargs: Any, error: str) -> None:
    with pytest.raises(ValueError, match=error):
        Interface.of(*args, **kwargs)
    with pytest.raises(TypeError, match="@message dataclass"):
        Interface.of("a/B", "x", types={"x": (int, None)})


def test_every_method_needs_one_handler_of_the_interface() -> None:
    with pytest.raises(ComponentError, match=r"Missing.svc: no handler for boom, slow"):

        class Missing(Component):
            svc = ServiceProvider(ECHO)

            @svc.method
            def echo(self, arg: Any) -> Any:
                return arg

    with pytest.raises(ComponentError, match=r"Stray.svc: run handles 'run', not a method"):

        class Stray(Component):
            svc = ServiceProvider(Interface.of("a/B", "x"))

            @svc.method("x")
            def x_(self, arg: Any) -> Any:
                return arg

            @svc.method
            def run(self, arg: Any) -> Any:
                return arg

    with pytest.raises(ComponentError, match=r"name reserved by Component"):

        class Reserved(Component):
            log = ServiceConsumer(ECHO)  # type: ignore[assignment]


def test_a_subclass_may_override_a_handler() -> None:
    class Louder(EchoService):
        @EchoService.svc.method("echo")
        def shout(self, arg: Any) -> Any:
            return str(arg).upper()

    replies: list[tuple[int, bool, Any]] = []
    port = Louder("L").provider("svc")
    port.serving = True
    port.serve(1, "echo", "hi", lambda *r: replies.append(r))
    assert replies == [(1, True, "HI")]


def test_service_ports_are_reported_with_role_interface_and_methods() -> None:
    info = {n: i.to_map() for n, i in EchoCaller.service_ports().items()}
    assert info["svc"] == {"role": "requires", "interface": ECHO.id, "methods": list(ECHO.methods)}
    assert PathPlanner.service_ports()["planner"].to_map()["role"] == "provides"
    assert EchoCaller.port_names() == {"in": [], "out": ["out"]}  # data ports only
    counters = EchoCaller("C").port_counters()
    assert counters["svc"] == {"calls": 0, "failed": 0, "timeouts": 0, "unavailable": 0}
    assert PathPlanner("P").port_counters()["planner"] == {"calls": 0, "failed": 0}


def test_a_provider_answers_only_while_serving_and_reports_handler_errors() -> None:
    planner = PathPlanner("P")
    planner.on_initialize()
    port = planner.provider("planner")
    replies: list[tuple[int, bool, Any]] = []

    def reply(*r: Any) -> None:
        replies.append(r)

    port.serve(1, "status", None, reply)
    assert replies.pop() == (1, False, ["ServiceUnavailable", "planner is not ACTIVE (CREATED)"])
    port.serving = True
    port.serve(2, "compute", [0.0, 0.0, 0.0, 1.0], reply)
    assert replies.pop() == (2, True, ([0.0, 0.0, 0.0], [0.0, 0.5, 1.0]))
    port.serve(3, "compute", [0.0, 0.0], reply)  # a wire Goal has 4 fields
    call_id, ok, (kind, text) = replies.pop()
    assert (call_id, ok, kind) == (3, False, "PortTypeError")
    assert "demo/Goal" in text
    assert (port.calls, port.failed) == (3, 2)
    flat_planner = PathPlanner("Flat", params={"step": 0.0})  # its handler raises
    flat_planner.on_initialize()
    flat = flat_planner.provider("planner")
    flat.serving = True
    flat.serve(4, "compute", [0.0, 0.0, 0.0, 1.0], reply)
    assert replies.pop() == (4, False, ["ValueError", "step must be > 0, got 0.0"])
    assert PLANNER.request_type("compute") is Goal


def test_errors_are_one_family() -> None:
    for cls in (ServiceError, ServiceTimeout, ServiceUnavailable):
        assert issubclass(cls, ServiceCallError)
    err = ServiceError("compute", "ValueError", "no path")
    assert str(err) == "compute: ValueError: no path"
