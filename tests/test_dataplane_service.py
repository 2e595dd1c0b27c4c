"""Service bindings over real loopback sockets: a provider's data server, a consumer's client.

Both ends run in this process (one event loop), each with the real parts: `DataServer` with a
provider component's `ServiceProviderRuntime`, `ServiceClient` bound to a consumer's
`ServiceCaller`; authenticated and encrypted on TCP as hosts started by an agent are.
"""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator, Callable
from pathlib import Path
from typing import Any

import msgpack
import pytest

from components.planner import PLANNER, Goal, PathPlanner, PlanCaller
from sdrpeer.dataplane import DataServer
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.dataplane.frames import FrameDecoder, Hello, encode_hello
from sdrpeer.dataplane.service import ServiceClient
from sdrpeer.keys.derive import data_key
from sdrpeer.sdk import (
    PortError,
    PortTypeError,
    ServiceCaller,
    ServiceError,
    ServiceProviderRuntime,
    ServiceRequestError,
    ServiceTimeout,
    ServiceUnavailable,
)
from tests.components_fixture import ECHO, OTHER_ECHO, EchoCaller, EchoService
from tests.wait import until_async

KEY = data_key(b"\x07" * 32)


class Provider:
    """A provider component's service port behind a real data server."""

    def __init__(self, server: DataServer, port: ServiceProviderRuntime) -> None:
        self.server = server
        self.port = port

    @property
    def tcp(self) -> str:
        return f"tcp://{self.server.addresses['tcp']}"


@pytest.fixture
async def providers(tmp_path: Path) -> AsyncIterator[Callable[..., Any]]:
    started: list[DataServer] = []

    async def start(*, keys: bool = True, active: bool = True, unix: bool = False) -> Provider:
        port = EchoService("Echo").provider("svc")
        port.serving = active
        server = DataServer(
            lambda name: None,
            resolve_service=lambda name: port if name == "svc" else None,
            unix_path=str(tmp_path / f"d{len(started)}.sock") if unix else None,
            auth=DataAuth([KEY] if keys else []),
        )
        await server.start()
        started.append(server)
        return Provider(server, port)

    yield start
    for server in started:
        await server.close()


def caller_for(to: str, *, keys: bool = True, other: bool = False) -> tuple[ServiceCaller, Any]:
    """An EchoCaller's `svc` (or `other`) port bound to a client dialing `to`."""
    comp = EchoCaller("Caller")
    name = "other" if other else "svc"
    caller = comp.consumer(name)
    iface = OTHER_ECHO if other else ECHO
    client = ServiceClient(
        "b1", to, "svc", f"Caller.{name}", iface.id, auth=DataAuth([KEY] if keys else [])
    )
    caller.bind(client)
    return caller, client


async def test_calls_answer_over_tcp_and_unix(providers: Callable[..., Any]) -> None:
    provider = await providers(unix=True)
    for to in (provider.tcp, f"unix://{provider.server.addresses['unix']}"):
        caller, client = caller_for(to)
        assert await caller.call("echo", {"a": [1, 2]}, timeout=2) == {"a": [1, 2]}
        assert await caller.echo(b"\x00" * 100_000, timeout=2) == b"\x00" * 100_000
        assert client.counters["replies"] == 2
        await client.close()
    assert provider.port.calls == 4
    assert provider.server.counters["accepted"] == 2


async def test_typed_methods_round_trip_their_messages() -> None:
    planner = PathPlanner("Planner")
    planner.on_initialize()
    port = planner.provider("planner")
    port.serving = True
    server = DataServer(lambda n: None, resolve_service={"planner": port}.get)
    await server.start()
    caller = PlanCaller("C").consumer("planner")
    to = f"tcp://{server.addresses['tcp']}"
    caller.bind(ServiceClient("b", to, "planner", "C.planner", PLANNER.id))
    try:
        path = await caller.call("compute", Goal(0.0, 0.0, 1.0, 0.0), timeout=2)
        assert path.xs == [0.0, 0.5, 1.0]
        assert path.ys == [0.0, 0.0, 0.0]
        with pytest.raises(PortTypeError, match="expected a demo/Goal"):
            await caller.call("compute", (0.0, 0.0, 1.0, 0.0))  # refused before it is sent
        with pytest.raises(PortError, match="no method 'plan'"):
            await caller.call("plan", None)
        assert (await caller.status(timeout=2))["computed"] == 1
    finally:
        await server.close()


async def test_provider_error_comes_back_and_the_provider_goes_on(
    providers: Callable[..., Any],
) -> None:
    provider = await providers()
    caller, _ = caller_for(provider.tcp)
    with pytest.raises(ServiceError) as info:
        await caller.call("boom", "no path", timeout=2)
    assert (info.value.kind, info.value.message, info.value.method) == (
        "ValueError",
        "no path",
        "boom",
    )
    assert await caller.call("echo", 7, timeout=2) == 7
    assert (provider.port.calls, provider.port.failed) == (2, 1)
    assert (caller.calls, caller.failed) == (2, 1)


async def test_no_reply_in_time_is_a_timeout_and_the_late_reply_is_dropped(
    providers: Callable[..., Any],
) -> None:
    provider = await providers()
    caller, client = caller_for(provider.tcp)
    with pytest.raises(ServiceTimeout, match=r"svc.slow: no reply within 0.05 s"):
        await caller.call("slow", 0.3, timeout=0.05)
    assert client.in_flight == 0
    await until_async("the late reply", lambda: client.counters["late"] == 1)
    assert await caller.call("echo", "after", timeout=2) == "after"


async def test_unavailable_when_unbound_unreachable_or_inactive(
    providers: Callable[..., Any],
) -> None:
    lone = EchoCaller("Lone").consumer("svc")
    with pytest.raises(ServiceUnavailable, match="not connected"):
        await lone.call("echo", 1)
    provider = await providers(active=False)
    caller, _ = caller_for(provider.tcp)
    with pytest.raises(ServiceUnavailable, match=r"svc is not ACTIVE \(CREATED\)"):
        await caller.call("echo", 1, timeout=2)
    to = provider.tcp
    await provider.server.close()
    gone, client = caller_for(to)
    with pytest.raises(ServiceUnavailable, match=f"provider at {to}"):
        await gone.call("echo", 1, timeout=2)
    assert client.counters["refused"] == 1


async def test_another_interface_or_no_key_is_refused(providers: Callable[..., Any]) -> None:
    provider = await providers()
    other, _ = caller_for(provider.tcp, other=True)
    with pytest.raises(ServiceUnavailable, match=r"interface mismatch: Caller.other requires "):
        await other.call("echo", 1, timeout=2)
    assert provider.server.counters["refused_interface"] == 1
    keyless, _ = caller_for(provider.tcp, keys=False)
    with pytest.raises(ServiceUnavailable, match="only takes authenticated connections"):
        await keyless.call("echo", 1, timeout=2)
    assert provider.server.counters["refused_auth"] == 1
    assert provider.port.calls == 0


async def test_repoint_fails_the_call_in_flight_and_sends_the_next_to_the_new_provider(
    providers: Callable[..., Any],
) -> None:
    old, new = await providers(), await providers()
    caller, client = caller_for(old.tcp)
    assert await caller.call("echo", 1, timeout=2) == 1
    slow = asyncio.ensure_future(caller.call("slow", 5.0, timeout=10))
    await until_async("the slow call running", lambda: old.port.running == 1)
    client.repoint(new.tcp)
    with pytest.raises(ServiceUnavailable, match="re-pointed to"):
        await slow
    assert await caller.call("echo", 2, timeout=2) == 2
    assert (old.port.calls, new.port.calls) == (1, 1)
    assert client.counters["lost"] == 1


async def test_a_lost_provider_fails_the_calls_in_flight(providers: Callable[..., Any]) -> None:
    provider = await providers()
    caller, client = caller_for(provider.tcp)
    slow = asyncio.ensure_future(caller.call("slow", 5.0, timeout=10))
    await until_async("the slow call running", lambda: provider.port.running == 1)
    await provider.server.close()
    with pytest.raises(ServiceUnavailable, match="connection to the provider was lost"):
        await slow
    with pytest.raises(ServiceUnavailable, match="provider at tcp://"):
        await caller.call("echo", 3, timeout=2)
    assert (client.counters["lost"], client.counters["dials"]) == (1, 2)


async def _raw(provider: Provider, frames: list[Any]) -> tuple[list[Any], bool]:
    """Open a plain (keyless) binding, write `frames`, read what comes back until EOF."""
    host, port = provider.server.addresses["tcp"].rsplit(":", 1)
    reader, writer = await asyncio.open_connection(host, int(port))
    hello = Hello("raw", "svc", "Raw.svc", {}, svc=ECHO.id)
    writer.write(encode_hello(hello))
    decoder = FrameDecoder()
    async with asyncio.timeout(5):
        while (reply := decoder.next_map()) is None:
            decoder.feed(await reader.read(4096))
    assert reply == {"ok": True}
    writer.write(b"".join(msgpack.packb(f) for f in frames))
    unpacker = msgpack.Unpacker()
    out: list[Any] = []
    closed = False
    async with asyncio.timeout(5):
        while len(out) < 1 and not closed:
            data = await reader.read(4096)
            closed = not data
            unpacker.feed(data)
            out.extend(unpacker)
    writer.close()
    return out, closed


async def test_malformed_requests_are_answered_or_refused_never_a_crash(
    providers: Callable[..., Any],
) -> None:
    provider = await providers(keys=False)
    out, _ = await _raw(provider, [[5, "just a value"]])
    assert out == [[5, False, ["ProtocolError", "expected [call_id, method, arg]"]]]
    assert provider.server.counters["refused_call"] == 1
    out, closed = await _raw(provider, [[6, 42, None]])
    assert (out, closed) == ([], True)
    assert provider.server.counters["refused_malformed"] == 1
    out, _ = await _raw(provider, [[7, "nope", None]])
    assert out == [[7, False, ["UnknownMethod", "no method 'nope' (have: echo, boom, slow)"]]]
    caller, _ = caller_for(provider.tcp, keys=False)
    assert await caller.call("echo", "still here", timeout=2) == "still here"


@pytest.fixture
async def silent() -> AsyncIterator[str]:
    """The address of a TCP listener that accepts and never answers (a dial that hangs)."""
    accepted: list[asyncio.StreamWriter] = []

    async def never_answer(_: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        accepted.append(writer)

    server = await asyncio.start_server(never_answer, "127.0.0.1", 0)
    yield f"tcp://127.0.0.1:{server.sockets[0].getsockname()[1]}"
    for writer in accepted:
        writer.close()
    server.close()
    await server.wait_closed()


def caller_dialing(to: str, dial_timeout: float) -> tuple[ServiceCaller, ServiceClient]:
    """An EchoCaller's `svc` port bound to a client that will dial `to`."""
    caller = EchoCaller("Caller").consumer("svc")
    client = ServiceClient(
        "b1", to, "svc", "Caller.svc", ECHO.id, auth=DataAuth([KEY]), dial_timeout=dial_timeout
    )
    caller.bind(client)
    return caller, client


async def test_a_repoint_while_dialing_sends_the_next_call_to_the_new_address(
    providers: Callable[..., Any], silent: str
) -> None:
    new = await providers()
    caller, client = caller_dialing(silent, dial_timeout=1.0)
    first = asyncio.ensure_future(caller.call("echo", 1, timeout=5))
    await until_async("the first dial", lambda: client.counters["dials"] == 1)
    client.repoint(new.tcp)
    assert await caller.call("echo", 2, timeout=0.9) == 2  # before the old dial gives up
    with pytest.raises(ServiceUnavailable, match=r"provider at tcp://127\.0\.0\.1:"):
        await first
    assert new.port.calls == 1


async def test_closing_a_binding_while_it_dials_fails_the_call_as_unavailable(
    silent: str,
) -> None:
    """Not a cancel: that would end the caller's execution context without an error."""
    caller, client = caller_dialing(silent, dial_timeout=10.0)
    call = asyncio.ensure_future(caller.call("echo", 1, timeout=10))
    await until_async("the dial", lambda: client.counters["dials"] == 1)
    await client.close()
    with pytest.raises(ServiceUnavailable, match="closed while connecting"):
        await call
    assert caller.unavailable == 1


async def test_an_argument_that_cannot_be_sent_is_a_request_error(
    providers: Callable[..., Any],
) -> None:
    provider = await providers()
    caller, _ = caller_for(provider.tcp)
    with pytest.raises(ServiceRequestError, match="unencodable"):
        await caller.call("echo", object(), timeout=2)
    assert await caller.call("echo", "fine", timeout=2) == "fine"  # the binding is intact
