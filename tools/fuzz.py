"""Fuzz the surfaces a peer, a host, a file or a client can reach: gossip datagrams, the control
channel (both directions), port streams, the system, robot and scenario YAML loaders, and the
HTTP API.

Usage: python tools/fuzz.py [--inputs 100000] [--seed 1]
                            [--only gossip,control,stream,system,robot,scenario,http]
                            [--json out.json]

How it works: each surface gets `--inputs` inputs, a third each of
- random bytes (any length up to a few kB);
- byte mutations of valid inputs (flip, insert, delete, duplicate or truncate a span);
- structure mutations: a valid message decoded, one node of its msgpack tree replaced by a
  hostile value (huge, negative or fractional numbers, NaN, long strings, bytes, deep nesting,
  wrong types), removed or duplicated, and encoded again.
Gossip inputs are sealed with the cluster key after mutation (with a fresh sequence number, by
the codec's `seal`, addressed to the robot fuzzed or to no robot at random), so they get past
authentication and reach the parser, the replay guard, the membership core (which
processes them, with its timers run every 64 inputs) and the record decoder. Control inputs go
to the agent's report decoder and to the host's command decoder; stream inputs to the receiver's
hello (with acknowledgement and authentication fields) and frame decoder, and replies to the
sender's reply parser. YAML inputs start from the example files: a hostile snippet spliced in
(aliases, tags, deep nesting, control characters, unrepresentable numbers), byte mutations, or
the document loaded, one node replaced by a hostile value and dumped again; they go to the
loader's parser. HTTP inputs (random bytes, byte and tree mutations of valid bodies, hostile
names and queries) go to a real agent's routes in this process (see `HTTP_ROUTES`); a 4xx is a
refusal, a 5xx other than 503 or no answer within 5 s a crash. An input may be refused only
with the surface's own error (WireError, RecordError, ProtocolError, FrameError, ConfigError,
HttpRefused), which is counted by reason; any other exception is a crash (reported with the
input). Also reported: the slowest input (a hang would show) and the peak RSS of this process.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import random
import resource
import sys
import time
from collections import Counter
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack
import yaml

from sdrpeer.control import messages as control
from sdrpeer.control.agent_side import ControlDecoder as AgentDecoder
from sdrpeer.control.codec import to_map
from sdrpeer.control.host_side import ControlDecoder as HostDecoder
from sdrpeer.dataplane.frames import (
    AckOffer,
    FrameDecoder,
    Hello,
    encode_frame,
    encode_hello,
    encode_reply,
    parse_hello,
    parse_reply,
    reply_auth,
)
from sdrpeer.deploy.handoff_rules import StateMsg
from sdrpeer.errors import ConfigError, FrameError, ProtocolError, RecordError, WireError
from sdrpeer.gossip.config import lan
from sdrpeer.gossip.core import Membership
from sdrpeer.gossip.events import RecordChanged
from sdrpeer.gossip.messages import (
    SUSPECT,
    Ack,
    Alive,
    Dead,
    Event,
    Gossip,
    Ping,
    PingReq,
    Record,
    Suspect,
    Sync,
)
from sdrpeer.gossip.wire import Codec, format_key, packet_body
from sdrpeer.keys.keyring import Keyring
from sdrpeer.monitor.scenario import Scenario
from sdrpeer.monitor.virtual import RobotFile
from sdrpeer.record.robot import decode_record, encode_record, reference_record
from sdrpeer.system.loader import parse_system

NOW = 1_800_000_000.0
REPO = Path(__file__).resolve().parent.parent


# -- hostile values and mutations ---------------------------------------------------------------


def hostile(rng: random.Random, depth: int = 0) -> Any:
    """A value meant to break a parser that trusts types and sizes."""
    pick = rng.randrange(14 if depth < 3 else 10)
    if pick == 0:
        return rng.choice([0, -1, 1, 2**31, 2**63 - 1, -(2**63), 2**64 - 1])
    if pick == 1:
        return rng.randint(-(2**40), 2**40)
    if pick == 2:
        return rng.choice([math.nan, math.inf, -math.inf, -0.0, 1e308, 0.5])
    if pick == 3:
        return "".join(chr(rng.randrange(32, 0x2FFF)) for _ in range(rng.randrange(0, 40)))
    if pick == 4:
        return "x" * rng.choice([256, 1000, 70_000])
    if pick == 5:
        return rng.randbytes(rng.randrange(0, 64))
    if pick == 6:
        return None
    if pick == 7:
        return rng.random() < 0.5
    if pick == 8:
        return ""
    if pick == 9:
        return rng.randbytes(rng.choice([300, 5000]))
    if pick == 10:
        return [hostile(rng, depth + 1) for _ in range(rng.randrange(0, 6))]
    if pick == 11:
        return {str(hostile(rng, 3)): hostile(rng, depth + 1) for _ in range(rng.randrange(0, 4))}
    if pick == 12:
        nested: Any = 1
        for _ in range(rng.randrange(10, 60)):
            nested = [nested]
        return nested
    return {hostile(rng, 3) if rng.random() < 0.3 else "t": hostile(rng, depth + 1)}


def mutate_tree(rng: random.Random, value: Any) -> Any:
    """`value` with one node replaced, removed or duplicated."""
    if isinstance(value, list) and value and rng.random() < 0.8:
        i = rng.randrange(len(value))
        out = list(value)
        action = rng.randrange(4)
        if action == 0:
            out[i] = hostile(rng)
        elif action == 1:
            del out[i]
        elif action == 2:
            out.insert(i, out[i])
        else:
            out[i] = mutate_tree(rng, out[i])
        return out
    if isinstance(value, dict) and value and rng.random() < 0.8:
        out_map = dict(value)
        key = rng.choice(list(out_map))
        action = rng.randrange(4)
        if action == 0:
            out_map[key] = hostile(rng)
        elif action == 1:
            del out_map[key]
        elif action == 2:
            out_map[hostile(rng, 3) if rng.random() < 0.5 else key + "x"] = hostile(rng)
        else:
            out_map[key] = mutate_tree(rng, out_map[key])
        return out_map
    return hostile(rng)


def mutate_bytes(rng: random.Random, data: bytes) -> bytes:
    """`data` with a span flipped, inserted, deleted, duplicated or the tail cut."""
    b = bytearray(data)
    n = len(b)
    action = rng.randrange(5)
    i = rng.randrange(n + 1)
    span = rng.randrange(1, 9)
    if action == 0 and n:
        for k in range(i, min(n, i + span)):
            b[k] ^= 1 << rng.randrange(8)
    elif action == 1:
        b[i:i] = rng.randbytes(span)
    elif action == 2:
        del b[i : i + span]
    elif action == 3:
        b[i:i] = b[i : i + span * 8]
    else:
        del b[i:]
    return bytes(b)


def unpack_all(data: bytes) -> list[Any]:
    """Every msgpack value of a valid concatenation."""
    return list(msgpack.Unpacker(raw=False, strict_map_key=False, use_list=True).feed(data) or [])


def _values(data: bytes) -> list[Any]:
    unpacker = msgpack.Unpacker(raw=False, strict_map_key=False)
    unpacker.feed(data)
    return list(unpacker)


def pack_all(values: list[Any]) -> bytes | None:
    """The values packed again (None if one cannot be: the mutation is skipped)."""
    try:
        return b"".join(msgpack.packb(v, use_bin_type=True) for v in values)
    except (TypeError, ValueError, OverflowError):
        return None


# -- the surfaces ----------------------------------------------------------------------------


class GossipSurface:
    """Signed datagrams -> Codec.decode -> Membership.receive -> decode_record."""

    errors = (WireError, RecordError)

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        self.keyring = Keyring([Keyring.generate()])
        self.sender = Codec("robot-2", self.keyring)
        self.codec = Codec("robot-1", self.keyring)
        self.core = Membership("robot-1", ("10.0.0.1", 7946), lan(), now=0.0, rng=rng)
        self.now = 0.0
        self.seq = 1
        self.sealed = 0
        record = encode_record(reference_record(peers=3, instances=3))
        alive = Alive("robot-2", ("10.0.0.2", 7946), 1)
        trap = Event("robot-2", 9, "trap", b"\x93\x01\x02\x03")
        ups = (alive, Suspect("robot-3", 2, "robot-2"), Dead("robot-4", 1, "robot-2"),
               Record("robot-2", 5, record), trap)  # fmt: skip
        entry = ("robot-2", ("10.0.0.2", 7946), 0, SUSPECT, 5)
        self.seeds = [
            packet_body(Ping("robot-2", 7, "robot-1", ups[:2]), 1, 1),
            packet_body(PingReq("robot-2", 8, "robot-3", ("10.0.0.3", 7946), True, ups[2:3]), 1, 1),
            packet_body(Ack("robot-2", 7, ups), 1, 1),
            packet_body(Gossip("robot-2", ups), 1, 1),
            packet_body(Sync("robot-2", False, (entry,), ups[3:4]), 1, 1),
        ]  # fmt: skip
        self.records = [record]

    def input(self, kind: int) -> bytes:
        rng = self.rng
        if kind == 0:
            return rng.randbytes(rng.randrange(0, 3000))
        body = rng.choice(self.seeds)
        if kind == 1:
            return self.seal(mutate_bytes(rng, body), fresh=False)
        values = _values(body)
        k = rng.randrange(len(values))
        values[k] = mutate_tree(rng, values[k])
        packed = pack_all(values)
        return self.seal(packed if packed is not None else body, fresh=True)

    def seal(self, body: bytes, *, fresh: bool) -> bytes:
        if fresh:  # a new seq and a current time in the head, so the replay guard lets it by
            values = _values(body) if body else []
            if values and isinstance(values[0], list) and len(values[0]) >= 4:
                self.seq += 1
                values[0][2], values[0][3] = self.seq, int(NOW * 1000)
                body = pack_all(values) or body
        self.sealed += 1  # the nonce's seq: unique per datagram, whatever the body's says
        return self.sender.seal(body, self.rng.choice(("robot-1", "")), self.sealed)

    def feed(self, data: bytes) -> None:
        packet = self.codec.decode(data, NOW)
        self.now += 0.01
        self.core.receive(self.now, ("10.0.0.2", 7946), packet)
        if self.seq % 64 == 0:
            self.core.handle_timer(self.now + 5.0)
        self.core.datagrams_to_send()
        while (event := self.core.next_event()) is not None:
            if isinstance(event, RecordChanged):
                decode_record(event.payload)

    def reasons(self) -> Counter[str]:
        return Counter({k: v for k, v in self.codec.counters.items() if k != "accepted"})


class ControlSurface:
    """Byte streams -> the agent's report decoder, and -> the host's command decoder."""

    errors = (ProtocolError,)

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        hello = control.Hello(
            pid=42, component="C", ports={"in": [], "out": ["o"]}, params={}, data={"tcp": "h:1"}
        )
        self.seeds = [
            to_map(hello),
            to_map(control.State("ACTIVE", 1.5)),
            to_map(control.Reply(3, True)),
            to_map(control.Heartbeat(2.0, {"out": {"frames_out": 1, "bytes_out": 9}})),
            to_map(control.Fault("emergency_stop", "x", 1.0)),
            to_map(control.Part(5, b"abc")),
            to_map(control.Activate(), 1),
            to_map(control.Connect(control.Conn("c", "o", "tcp://h:1", "i")), 2),
            to_map(control.Restore(3), 5),
        ]
        self.reasons: Counter[str] = Counter()

    def input(self, kind: int) -> bytes:
        rng = self.rng
        if kind == 0:
            return rng.randbytes(rng.randrange(0, 3000))
        msgs = rng.sample(self.seeds, rng.randrange(1, 4))
        if kind == 1:
            return mutate_bytes(rng, b"".join(msgpack.packb(m, use_bin_type=True) for m in msgs))
        values: list[Any] = [dict(m) for m in msgs]
        k = rng.randrange(len(values))
        values[k] = mutate_tree(rng, values[k])
        return pack_all(values) or b""

    def feed(self, data: bytes) -> None:
        failures: list[ProtocolError] = []
        for side, decoder in (("agent", AgentDecoder()), ("host", HostDecoder())):
            try:
                decoder.feed(data)
            except ProtocolError as error:
                failures.append(error)
                self.reasons[f"{side}: {type(error).__name__}"] += 1
        if failures:
            raise failures[0]


class StreamSurface:
    """A connection's bytes -> the receiver's hello and frame decoder."""

    errors = (FrameError,)

    def __init__(self, rng: random.Random) -> None:
        self.rng = rng
        policy = {"push": "fifo", "buffer": 4}
        hello = encode_hello(Hello("c1", "image", "Cam.image", policy))
        full = encode_hello(
            Hello("c1", "image", "Cam.image", policy, ack=AckOffer("ab12", 7), auth=b"n" * 16)
        )
        frames = b"".join(
            encode_frame(i, v) for i, v in enumerate([1, b"\x00" * 300, "x", {"a": [1]}], 1)
        )
        reply = encode_reply(None, shm=True, ack=True, auth=(b"r" * 16, b"p" * 16))
        proof = msgpack.packb({"auth": b"p" * 16})
        self.seeds = [
            hello + frames,
            hello,
            hello + encode_frame(1, b"\x01" * 5000),
            full + proof + frames,
            reply + msgpack.packb([5]) + msgpack.packb(123),
        ]
        self.reasons: Counter[str] = Counter()

    def input(self, kind: int) -> bytes:
        rng = self.rng
        if kind == 0:
            return rng.randbytes(rng.randrange(0, 3000))
        seed = rng.choice(self.seeds)
        if kind == 1:
            return mutate_bytes(rng, seed)
        values = _values(seed)
        k = rng.randrange(len(values))
        values[k] = mutate_tree(rng, values[k])
        return pack_all(values) or b""

    def feed(self, data: bytes) -> None:
        decoder = FrameDecoder(max_frame=64 * 1024)
        try:
            cut = self.rng.randrange(len(data) + 1)
            decoder.feed(data[:cut])
            first = decoder.next_map()
            decoder.feed(data[cut:])
            if first is None:
                first = decoder.next_map()
            if first is not None:
                if isinstance(first, dict) and "ok" in first:  # a reply (the sender's side)
                    parse_reply(first)
                    reply_auth(first)
                else:
                    parse_hello(first)
                    decoder.next_map()  # a proof, when the hello has auth
                decoder.frames()
        except FrameError as exc:
            self.reasons[exc.reason] += 1
            raise


YAML_SNIPPETS = (
    "&a [*a]",
    "!!python/object/apply:os.system [true]",
    "!custom x",
    "[" * 200 + "]" * 200,
    "{a: " * 80 + "1" + "}" * 80,
    "\x00",
    "\x07",
    "*undefined",
    "&x [1, 2]",
    "? [a, b]\n: 1",
    "{[a]: 1}",
    "1e400",
    "-99999999999999999999999999",
    ".nan",
    "-.inf",
    "'" + "x" * 5000 + "'",
    "2001-12-14t21:59:43.10-05:00",
    "!!binary aGVsbG8=",
    "|\n  block\n  text",
    "- - - -",
    ": :",
    "%YAML 1.1\n---",
    "--- a\n--- b",
)
"""Pieces of hostile YAML spliced into valid files (aliases, tags, nesting, control
characters, numbers no type holds, several documents)."""


class YamlSurface:
    """YAML text -> one of the project's loaders (system, robot or scenario file)."""

    errors = (ConfigError,)

    def __init__(self, rng: random.Random, seeds: list[Path], parse: Callable[[str], Any]) -> None:
        self.rng = rng
        self.seeds = [p.read_text() for p in seeds]
        self.trees = [yaml.safe_load(t) for t in self.seeds]
        self.parse = parse
        self.reasons: Counter[str] = Counter()

    def input(self, kind: int) -> bytes:
        rng = self.rng
        if kind == 0:  # a hostile snippet spliced in at a random line, as a value or a line
            lines = rng.choice(self.seeds).splitlines()
            i = rng.randrange(len(lines) + 1)
            piece = rng.choice(YAML_SNIPPETS)
            if i < len(lines) and ":" in lines[i] and rng.random() < 0.7:
                key = lines[i].split(":", 1)[0]
                lines[i] = f"{key}: {piece}"
            else:
                lines.insert(i, piece)
            return "\n".join(lines).encode("utf-8", "surrogatepass")
        if kind == 1:
            return mutate_bytes(rng, rng.choice(self.seeds).encode())
        tree = mutate_tree(rng, rng.choice(self.trees))
        try:
            return yaml.safe_dump(tree, allow_unicode=True).encode("utf-8", "surrogatepass")
        except (yaml.YAMLError, TypeError, ValueError, RecursionError):
            return b""

    def feed(self, data: bytes) -> None:
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            self.reasons["not utf-8"] += 1
            raise ConfigError("not UTF-8") from None
        try:
            self.parse(text)
        except ConfigError as exc:
            message = str(exc)
            key = message.split(": ", 2)[1] if message.count(": ") >= 2 else message
            self.reasons[key.split("'")[0][:40]] += 1
            raise


def _system_surface(rng: random.Random) -> YamlSurface:
    seeds = sorted((REPO / "examples/paper").glob("*.yaml"))
    return YamlSurface(rng, seeds, lambda t: parse_system(t, str(REPO / "examples/paper/x.yaml")))


def _robot_surface(rng: random.Random) -> YamlSurface:
    return YamlSurface(
        rng, sorted((REPO / "examples/robots").glob("*.yaml")), lambda t: RobotFile.parse(t, "r")
    )


def _scenario_surface(rng: random.Random) -> YamlSurface:
    seeds = sorted((REPO / "examples/scenarios").glob("*.yaml"))
    return YamlSurface(rng, seeds, lambda t: Scenario.parse(t, "s"))


class HttpRefused(Exception):
    """A 4xx answer: the route refused the request (the status is the reason)."""


_DEPLOYABLE = json.loads(
    json.dumps(
        parse_system(
            "name: fuzz\ncomponents:\n  - {name: Cam, target: components.camera:Camera,"
            " params: {rate: 2}, standby: {same_robot: 1}}\n",
            "fuzz.yaml",
        ).to_json()
    )
)
"""A system `/v1/deploy` takes (every valid input is allocated; none launches: see below)."""

HTTP_ROUTES: list[tuple[str, str, Any]] = [
    # (method, path with {q} for a fuzzed query or {n} for a fuzzed name, seed JSON body)
    ("POST", "/v1/robot", {"battery": "30%", "rssi": "-60dBm", "pos": [1, 2]}),
    ("POST", "/v1/robot", {"memory": "2GB", "drain": "1%/min"}),
    ("POST", "/v1/recovery", {"robot": "robot-1", "component": "Cam", "instance": "Cam",
                              "action": "standby_other_robot"}),
    ("POST", "/v1/move", {"component": "Cam", "to": "robot-2"}),
    ("POST", "/v1/plan", {"plan": {"epoch": 0, "version": 0}}),
    ("POST", "/v1/deploy", {"system": {"name": "x", "components": []}}),
    ("POST", "/v1/deploy", {"system": _DEPLOYABLE}),
    ("POST", "/v1/instances", {"instances": [{"name": "Cam", "launcher": "python",
                               "target": "components.camera:Camera", "params": {"rate": 2}}],
                               "replace": False}),
    ("POST", "/v1/instances", {"instances": [{"name": "Sh", "launcher": "exec",
                               "target": ["/bin/sh", "-c", "exit 0"]}]}),
    ("POST", "/v1/undeploy", {}),
    ("POST", "/v1/state", StateMsg("sync", "Cam", "Cam", "Cam-s1", (1, "robot-1", 1),
                                   {"n": 1, "pose": [0.5, 1.5]}, "robot-2").encode()),
    ("POST", "/v1/instances/{n}/activate", None),
    ("POST", "/v1/instances/{n}/deactivate", None),
    ("POST", "/v1/instances/{n}/reset", None),
    ("POST", "/v1/instances/{n}/restart", None),
    ("POST", "/v1/instances/{n}/{n}", None),
    ("DELETE", "/v1/instances/{n}", None),
    ("POST", "/v1/ports/connect", {"from": "Cam.image", "to": "Det.in", "policy": {"buffer": 2}}),
    ("POST", "/v1/ports/disconnect", {"id": "Cam.image->Det.image"}),
    ("POST", "/v1/ports/tap", {"ports": ["Cam.image"], "count": 1, "duration": 1,
                               "decode": True}),
    ("POST", "/v1/ports/inject", {"port": "Det.image", "value": {"x": 1}, "count": 1}),
    ("POST", "/v1/ports/feed?port={n}.inp&type=", msgpack.packb([0, {"x": b"1"}])),
    ("GET", "/v1/ports", None),
    ("GET", "/v1/events?{q}", None),
    ("GET", "/v1/history?{q}", None),
    ("GET", "/v1/instances/{n}/logs?{q}", None),
    ("GET", "/v1/instances", None),
    ("GET", "/v1/members", None),
    ("GET", "/v1/status", None),
    ("GET", "/v1/plan", None),
    ("GET", "/v1/agent", None),
    ("GET", "/dashboard/{n}", None),
    ("GET", "/healthz", None),
    ("GET", "/metrics", None),
]  # fmt: skip
"""What the HTTP surface sends: every state-changing route (JSON bodies, and the msgpack state
message of POST /v1/state) and every read but the SSE stream. The fuzzed agent allows no launcher
(`allow_targets: []` turns python off), so a valid POST /v1/instances is refused (403) and a
deployable system is infeasible: no input launches a host."""


class HttpSurface:
    """Bodies, names and queries -> a real agent's API in this process (alone in its cluster, a
    virtual robot, the token given): every answer below 500, within 5 s."""

    errors = (HttpRefused,)

    def __init__(self, rng: random.Random) -> None:
        import asyncio  # noqa: PLC0415 - only this surface runs a loop
        import tempfile  # noqa: PLC0415

        from sdrpeer.agent.agent import Agent  # noqa: PLC0415 - the agent is heavy to import
        from sdrpeer.config import AgentConfig  # noqa: PLC0415

        self.rng = rng
        self.reasons: Counter[str] = Counter()
        self.dir = Path(tempfile.mkdtemp(prefix="sdrpeer-fuzz-http-"))
        (self.dir / "robot.yaml").write_text("name: robot-1\nmemory: 4GB\nbattery: 80%\n")
        (self.dir / "cluster.key").write_text(format_key(Keyring.generate()) + "\n")
        os.chmod(self.dir / "cluster.key", 0o600)
        config = AgentConfig(
            name="robot-1",
            bind="127.0.0.1:0",
            api="127.0.0.1:0",
            robot_file=self.dir / "robot.yaml",
            key_file=self.dir / "cluster.key",
            preset="fast_test",
            allow_targets=(),  # nothing may launch: valid specs are refused, not run
            data_dir=self.dir / "data",
        )
        self.loop = asyncio.new_event_loop()
        self.agent = Agent(config)
        self.loop.run_until_complete(self.agent.start())
        self.token = (self.dir / "data" / "token").read_text().strip()
        assert self.agent.api_url is not None
        self.base = self.agent.api_url.rstrip("/")
        self.session = self.loop.run_until_complete(self._session())
        self.loop.run_until_complete(self._elected())

    async def _elected(self) -> None:
        """Wait (10 s at most) until the agent holds the allocator role: before, the deployment
        routes rightly answer 503."""
        import asyncio  # noqa: PLC0415

        def elected() -> bool:
            c = self.agent.coordinator
            return c is not None and c.election.is_allocator()

        async with asyncio.timeout(10):
            while not elected():  # noqa: ASYNC110 - polls a plain attribute
                await asyncio.sleep(0.05)

    async def _session(self) -> Any:
        import aiohttp  # noqa: PLC0415

        return aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=5))

    def input(self, kind: int) -> bytes:
        rng = self.rng
        route = rng.randrange(len(HTTP_ROUTES))
        seed = HTTP_ROUTES[route][2]
        if kind == 0 or seed is None:
            body = rng.randbytes(rng.randrange(0, 300))
        elif isinstance(seed, bytes):  # msgpack: its bytes, or its tree, mutated
            if kind == 1:
                body = mutate_bytes(rng, seed)
            else:
                try:
                    tree = mutate_tree(rng, msgpack.unpackb(seed, raw=False))
                    body = msgpack.packb(tree, use_bin_type=True, default=repr)
                except (TypeError, ValueError, RecursionError, OverflowError):
                    body = seed[: rng.randrange(1, len(seed))]
        elif kind == 1:
            body = mutate_bytes(rng, json.dumps(seed).encode())
        else:
            try:
                body = json.dumps(mutate_tree(rng, seed), default=repr).encode()
            except (TypeError, ValueError, RecursionError):  # not JSON-able: send the seed cut
                body = json.dumps(seed).encode()[: rng.randrange(1, 40)]
        name = rng.choice(["Cam", "x" * 300, "..", "%00", "a/b", "ü", ""])
        query = rng.choice(["since=-1", "limit=0", "limit=abc&since=9e99", "follow=1&lines=-5",
                            "since=1&limit=10", "x=" + "y" * 3000, "%ff%fe"])  # fmt: skip
        return bytes([route]) + name.encode() + b"\x00" + query.encode() + b"\x00" + body

    def feed(self, data: bytes) -> None:
        route = data[0] % len(HTTP_ROUTES)
        name, query, body = data[1:].split(b"\x00", 2)
        method, path, _ = HTTP_ROUTES[route]
        path = path.replace("{n}", name.decode()).replace("{q}", query.decode())
        status = self.loop.run_until_complete(self._call(method, path, body))
        if status >= 500 and status != 503:  # 503: "try again later", a designed answer
            raise RuntimeError(f"{method} {path}: {status}")
        if status >= 400:
            self.reasons[f"{status}"] += 1
            raise HttpRefused(status)

    async def _call(self, method: str, path: str, body: bytes) -> int:
        import aiohttp  # noqa: PLC0415

        headers = {"Authorization": f"Bearer {self.token}"}
        try:
            async with self.session.request(
                method, self.base + path, data=body, headers=headers
            ) as response:
                await response.read()
                return int(response.status)
        except (aiohttp.InvalidURL, ValueError):
            return 400  # the client refused to send it: nothing reached the agent
        except TimeoutError:
            return 599  # a hang: counted as a crash

    def close(self) -> None:
        import shutil  # noqa: PLC0415

        self.loop.run_until_complete(self.session.close())
        self.loop.run_until_complete(self.agent.stop(leave=False))
        self.loop.close()
        shutil.rmtree(self.dir, ignore_errors=True)


SURFACES: dict[str, Callable[[random.Random], Any]] = {
    "gossip": GossipSurface,
    "control": ControlSurface,
    "stream": StreamSurface,
    "system": _system_surface,
    "robot": _robot_surface,
    "scenario": _scenario_surface,
    "http": HttpSurface,
}


def fuzz(name: str, inputs: int, seed: int) -> dict[str, Any]:
    """Run one surface; its figures."""
    rng = random.Random(seed)
    surface = SURFACES[name](rng)
    crashes: list[dict[str, Any]] = []
    refused = slowest = 0.0
    accepted = 0
    t0 = time.perf_counter()
    for i in range(inputs):
        data = surface.input(i % 3)
        start = time.perf_counter()
        try:
            surface.feed(data)
            accepted += 1
        except surface.errors:
            refused += 1
        except Exception as exc:  # a crash: what the surface must never do
            if len(crashes) < 20:
                crashes.append({"input": data[:200].hex(), "error": f"{type(exc).__name__}: {exc}"})
            else:
                crashes.append({})
        slowest = max(slowest, time.perf_counter() - start)
    elapsed = time.perf_counter() - t0
    if hasattr(surface, "close"):
        surface.close()
    reasons = surface.reasons() if callable(surface.reasons) else surface.reasons
    return {
        "surface": name,
        "inputs": inputs,
        "accepted": accepted,
        "refused": int(refused),
        "refused_by_reason": dict(sorted(reasons.items())),
        "crashes": len(crashes),
        "crash_samples": [c for c in crashes if c][:5],
        "slowest_input_ms": round(slowest * 1000, 3),
        "inputs_per_s": round(inputs / elapsed),
        "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--inputs", type=int, default=100_000, help="inputs per surface")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--only", default=",".join(SURFACES))
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    logging.disable(logging.WARNING)  # the host decoder logs every map it ignores
    results = [fuzz(n, args.inputs, args.seed) for n in args.only.split(",") if n]
    print(f"{'surface':<9}{'inputs':>9}{'accepted':>10}{'refused':>9}{'crashes':>9}"
          f"{'slowest ms':>12}{'inputs/s':>10}{'peak RSS MiB':>14}")  # fmt: skip
    for r in results:
        print(f"{r['surface']:<9}{r['inputs']:>9}{r['accepted']:>10}{r['refused']:>9}"
              f"{r['crashes']:>9}{r['slowest_input_ms']:>12.2f}{r['inputs_per_s']:>10}"
              f"{r['peak_rss_mib']:>14.1f}")  # fmt: skip
        top = sorted(r["refused_by_reason"].items(), key=lambda kv: -kv[1])[:6]
        print("  refused: " + ", ".join(f"{k} {v}" for k, v in top))
        for c in r["crash_samples"]:
            print(f"  crash: {c['error']}  input {c['input'][:80]}...")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(results, indent=2))
        print(f"wrote {args.json}")
    return 1 if any(r["crashes"] for r in results) else 0


if __name__ == "__main__":
    sys.exit(main())
