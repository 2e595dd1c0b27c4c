"""The agent side: the pure report decoder, and the asyncio channel against the fake host."""

from __future__ import annotations

import asyncio
import os
import socket
import sys
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import msgpack
import pytest

from sdrpeer.control.agent_side import MAX_MESSAGE, ControlChannel, ControlDecoder, ProtocolError
from sdrpeer.control.messages import (
    Activate,
    Conn,
    Connect,
    Disconnect,
    Exit,
    Heartbeat,
    Hello,
    Report,
    State,
)
from sdrpeer.errors import CommandError
from tests.wait import until_async

FAKE_HOST = Path(__file__).with_name("fake_host.py")
WAIT = 5.0


def pack(msg: Any) -> bytes:
    return bytes(msgpack.packb(msg))


def test_decoder_reassembles_split_messages():
    d = ControlDecoder()
    data = pack({"t": "state", "state": "INACTIVE", "ts": 1.0, "error": None})
    data += pack({"t": "heartbeat", "ts": 2, "ports": {}, "x": 1})  # unknown keys are ignored
    data += pack({"t": "news", "id": 1})  # an unknown report is ignored
    assert d.feed(data[:5]) == []
    assert d.feed(data[5:]) == [State("INACTIVE", 1.0), Heartbeat(2.0, {})]
    assert d.ignored == 1


@pytest.mark.parametrize(
    ("message", "why"),
    [
        ([1, 2], "expected a map, got list"),
        ({"x": 1}, "without a str 't'"),
        ({"t": 5}, "without a str 't'"),
        ({"t": "hello", "protocol": 2, "pid": 1}, "hello: unknown protocol 2"),
        ({"t": "hello", "pid": "1"}, "hello: 'pid' must be an integer, got '1'"),
        ({"t": "state", "state": "RUNNING"}, "state: unknown state 'RUNNING'"),
        ({"t": "state", "state": "ERROR", "ts": True}, "state: 'ts' must be a number"),
        ({"t": "reply", "id": "1", "ok": True}, "reply: 'id' must be an integer"),
        ({"t": "reply", "id": 1}, "reply: no 'ok'"),
        ({"t": "heartbeat", "ts": 1, "ports": {"p": {"n": "1"}}}, "heartbeat: 'ports' must be"),
        ({"t": "fault", "kind": "k", "detail": 3}, "fault: 'detail' must be a string"),
        ({"t": "part", "of": "x", "data": b""}, "part: 'of' must be an integer"),
    ],
)
def test_decoder_refuses(message, why):
    with pytest.raises(ProtocolError, match=why):
        ControlDecoder().feed(pack(message))


def test_decoder_refuses_oversized_messages():
    with pytest.raises(ProtocolError, match="size limit"):
        ControlDecoder().feed(pack({"t": "fault", "detail": "x" * MAX_MESSAGE}))


def test_decoder_refuses_bytes_that_are_not_msgpack():
    with pytest.raises(ProtocolError):
        ControlDecoder().feed(b"\xc1")


@dataclass
class Link:
    """A channel to a running fake host, with what it reported."""

    channel: ControlChannel
    proc: asyncio.subprocess.Process
    reports: list[Report]
    closed: asyncio.Future[str | None]

    async def report(self, kind: type[Any], **match: Any) -> Any:
        """The first report of type `kind` with the given fields (bounded wait)."""

        def matches(r: Any) -> bool:
            return isinstance(r, kind) and all(getattr(r, k) == v for k, v in match.items())

        seen = await until_async(
            f"a {kind.__name__} report with {match}",
            lambda: list(self.reports),
            lambda reports: any(map(matches, reports)),
            within=WAIT,
            poll=0.01,
        )
        return next(r for r in seen if matches(r))


async def open_link(mode: str = "", reply_wait: float = WAIT) -> Link:
    parent, child = socket.socketpair()
    proc = await asyncio.create_subprocess_exec(
        sys.executable,
        str(FAKE_HOST),
        "--mode",
        mode,
        "--heartbeat",
        "0.1",
        pass_fds=(child.fileno(),),
        env={**os.environ, "SDRPEER_CONTROL_FD": str(child.fileno()), "SDRPEER_INSTANCE": "T"},
        stderr=asyncio.subprocess.DEVNULL,
    )
    child.close()
    reports: list[Report] = []
    closed: asyncio.Future[str | None] = asyncio.get_running_loop().create_future()

    def on_close(reason: str | None) -> None:
        if not closed.done():
            closed.set_result(reason)

    channel = ControlChannel(parent, reports.append, on_close, name="T", command_timeout=reply_wait)
    link = Link(channel, proc, reports, closed)
    await channel.open()
    return link


@pytest.fixture
async def links() -> AsyncIterator[list[Link]]:
    opened: list[Link] = []
    yield opened
    for link in opened:
        await link.channel.close()
        if link.proc.returncode is None:
            link.proc.kill()
        await link.proc.wait()


async def test_hello_state_heartbeat_and_command_replies(links):
    link = await open_link()
    links.append(link)
    hello = await link.report(Hello)
    assert hello.protocol == 1
    assert hello.pid == link.proc.pid
    assert hello.data["tcp"].startswith("127.0.0.1:")
    await link.report(State, state="INACTIVE")
    reply = await link.channel.command(Activate())
    assert reply.ok is True
    await link.report(State, state="ACTIVE")
    beat = await link.report(Heartbeat)
    assert beat.ports["out"] == {"frames_out": 1, "bytes_out": 10}
    conn = Conn("c1", "out", "tcp://127.0.0.1:9", "inp", {})
    await link.channel.command(Connect(conn))
    with pytest.raises(CommandError) as info:
        await link.channel.command(Disconnect("nope"))
    assert info.value.reason == "refused"
    await link.channel.command(Exit())
    assert await asyncio.wait_for(link.proc.wait(), WAIT) == 0
    assert await asyncio.wait_for(link.closed, WAIT) is None  # EOF, not an error


async def test_a_refused_command_says_so(links):
    link = await open_link("refuse")
    links.append(link)
    with pytest.raises(CommandError, match="refused") as info:
        await link.channel.command(Activate())
    assert info.value.detail == "no"


async def test_command_timeout(links):
    link = await open_link("no_reply", reply_wait=0.2)
    links.append(link)
    with pytest.raises(CommandError) as info:
        await link.channel.command(Activate())
    assert info.value.reason == "timeout"
    assert not link.channel.closed  # a slow host is not a protocol error


@pytest.mark.parametrize("mode", ["garbage", "oversize"])
async def test_protocol_error_closes_and_counts(links, mode):
    link = await open_link(mode)
    links.append(link)
    reason = await asyncio.wait_for(link.closed, WAIT)
    assert reason is not None
    assert reason.startswith("protocol error")
    assert link.channel.counters["protocol_errors"] == 1
    assert link.channel.closed
    with pytest.raises(CommandError, match="closed"):
        await link.channel.command(Activate())
    # the host sees EOF (or a broken pipe mid-send) and exits by itself
    await asyncio.wait_for(link.proc.wait(), WAIT)


async def test_pending_command_fails_when_the_host_dies(links):
    link = await open_link("no_reply", reply_wait=WAIT)
    links.append(link)
    await link.report(Hello)
    task = asyncio.create_task(link.channel.command(Activate()))
    await until_async(
        "activate sent", lambda: link.channel.pending_since({Activate.T}), lambda t: t is not None
    )
    link.proc.kill()
    with pytest.raises(CommandError) as info:
        await asyncio.wait_for(task, WAIT)
    assert info.value.reason == "closed"
