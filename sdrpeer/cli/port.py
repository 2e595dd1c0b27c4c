"""`sdrpeer port list|connect|disconnect|print|inject|record|replay`: the port tools.

How it works: every command is a client of the agent's /v1/ports routes (sdrpeer.ports.routes),
which does the work with the cluster's data keys; this side never holds one. `list` asks every
robot of the cluster (their API addresses from /v1/members). `print` and `record` read the
agent's tap stream (msgpack: a header, one `[index, received_ns, seq, value]` per frame, an end
map); `record` writes it to an MCAP file as it arrives (sdrpeer.ports.mcapfile), one channel
per port, in format `sdrpeer` (msgpack) or `ros2` (`--format ros2`: CDR, rosbag2's; every port
must be of a mapped type, checked on the tap's header before the file is opened). `replay`
reads a recording of either format and streams its messages to the agent's feed in file order,
each at its recorded log time scaled by `--speed` (0: as fast as the ports take them), as the
value's msgpack (a `sdrpeer` recording's bytes as recorded; a `ros2` one's decoded first, the
whole file before anything is sent, so a damaged message sends nothing).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import urllib.parse
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from sdrpeer.cli.common import client_for, parse_assignment, print_json
from sdrpeer.client import AgentClient
from sdrpeer.errors import ApiError, ConfigError, PortToolError, SdrpeerError
from sdrpeer.vocabulary import MemberState

RECORD_POLICY = {"push": "fifo", "full": "overwrite", "buffer": 256}
"""A recording keeps every frame in order unless the agent falls 256 behind (then the oldest
go, counted at the sender): it never blocks the robot."""


def _policy(items: list[str]) -> dict[str, Any]:
    return dict(parse_assignment(p) for p in items)


def cmd_list(args: argparse.Namespace) -> int:
    """Every port of every instance, on every robot the agent knows (or only its own)."""
    client = client_for(args)
    rows: list[dict[str, Any]] = []
    unreachable: list[str] = []
    if args.here:
        rows = list(client.get("/v1/ports"))
    else:
        for member in client.members():
            api = member.get("api")
            if member.get("state") not in (MemberState.ALIVE, MemberState.SUSPECT) or not api:
                continue
            try:
                rows.extend(AgentClient(str(api), client.token).get("/v1/ports"))
            except ApiError as e:
                unreachable.append(f"{member.get('name')}: {e}")
    if args.json:
        print_json(rows)
    else:
        print(format_ports(rows))
    for line in unreachable:
        print(f"warning: {line}", file=sys.stderr)
    return 0


def format_ports(rows: list[dict[str, Any]]) -> str:
    """The port table: robot, instance.port, direction, type, frames (a service port: calls),
    frames/s, connections."""
    header = ("ROBOT", "PORT", "DIR", "TYPE", "FRAMES", "HZ", "CONNECTIONS")
    lines = [header]
    keys = {
        "out": "frames_out",
        "in": "frames_in",
        "provides": "calls",
        "requires": "calls",
        "publishes": "frames_out",
    }
    for r in rows:
        key = keys.get(r["direction"], "frames_in")
        frames = (r.get("counters") or {}).get(key, 0)
        rate = (r.get("rates") or {}).get(f"{key}_per_s")
        ends = [
            ("+" if c.get("adhoc") else "") + str(c.get("to") or c.get("from"))
            for c in r.get("connections", [])
        ]
        lines.append(
            (
                str(r.get("robot", "")),
                f"{r['instance']} {r['port']}" if r.get("ros2") else f"{r['instance']}.{r['port']}",
                r["direction"],
                r.get("type") or "-",
                str(frames),
                "-" if rate is None else f"{rate:g}",
                ", ".join(ends) or "-",
            )
        )
    widths = [max(len(line[i]) for line in lines) for i in range(len(header) - 1)]
    out = ["  ".join(c.ljust(w) for c, w in zip(line, widths, strict=False)) for line in lines]
    out = [f"{o}  {line[-1]}" for o, line in zip(out, lines, strict=True)]
    return "\n".join(out) + ("\n(+ run-time connection)" if any("+" in o for o in out) else "")


def cmd_connect(args: argparse.Namespace) -> int:
    """Connect an OutPort to an InPort at run time."""
    body: dict[str, Any] = {"from": args.out, "to": args.inp, "policy": _policy(args.policy)}
    if args.id:
        body["id"] = args.id
    answer = client_for(args).post("/v1/ports/connect", body)
    print(f"connected {answer['from']} -> {answer['to']} (id {answer['id']})")
    return 0


def cmd_disconnect(args: argparse.Namespace) -> int:
    """Remove a run-time connection, by id or by its two ends."""
    one = args.inp is None
    body = {"id": args.id_or_out} if one else {"from": args.id_or_out, "to": args.inp}
    answer = client_for(args).post("/v1/ports/disconnect", body)
    print(f"disconnected {answer['removed']}")
    return 0


def _printable(value: Any) -> Any:
    """A value for JSON: bytes as {"bytes": length, "head": first 16 in hex}."""
    if isinstance(value, bytes):
        return {"bytes": len(value), "head": value[:16].hex()}
    if isinstance(value, dict):
        return {str(k): _printable(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_printable(v) for v in value]
    return value


def _tap(args: argparse.Namespace, ports: list[str], body: dict[str, Any]) -> Iterator[Any]:
    body = {"ports": ports, **body}
    if args.count is not None:
        body["count"] = args.count
    if args.duration is not None:
        body["duration"] = args.duration
    return client_for(args).stream("/v1/ports/tap", body)


def cmd_print(args: argparse.Namespace) -> int:
    """Print what an OutPort sends, one JSON line per frame (rtprint, `ros2 topic echo`)."""
    body: dict[str, Any] = {"decode": not args.raw}
    if args.policy:
        body["policy"] = _policy(args.policy)
    stream = _tap(args, [args.port], body)
    header = next(stream, None)
    if not isinstance(header, dict):
        raise SdrpeerError("the agent's tap sent no header")
    for item in stream:
        if isinstance(item, dict):
            if item.get("dropped"):
                print(f"({item['dropped']} frames dropped: printing was too slow)", file=sys.stderr)
            break
        _, received, seq, value = item
        line = {"port": args.port, "seq": seq, "t": received / 1e9, "value": _printable(value)}
        print(json.dumps(line, sort_keys=True), flush=True)
    return 0


def cmd_inject(args: argparse.Namespace) -> int:
    """Send a value (JSON or YAML; a typed port's as a map of its fields) to an InPort."""
    import yaml  # noqa: PLC0415 - the parser stays light (sdrpeer.cli.main)

    try:
        value = yaml.safe_load(args.value)
    except yaml.YAMLError as e:
        raise ConfigError(f"VALUE: not JSON or YAML: {e}") from None
    body: dict[str, Any] = {"port": args.port, "value": value, "count": args.count}
    if args.rate is not None:
        body["rate"] = args.rate
    answer = client_for(args).request("POST", "/v1/ports/inject", body)
    print(f"sent {answer['sent']} value(s) to {answer['port']}")
    return 0


def record(
    client: AgentClient,
    ports: list[str],
    path: Path,
    body: dict[str, Any],
    fmt: str = "sdrpeer",
) -> dict[str, Any]:
    """Tap `ports` (the tap's `body`: count, duration, policy) and write what comes to an MCAP
    file at `path` in format `fmt` (`sdrpeer` or `ros2`); what was recorded: frames, bytes,
    seconds, the first and last log times, the end map (why it ended, dropped). PortToolError,
    and no file, when a port cannot be recorded in that format."""
    from sdrpeer.ports import mcapfile  # noqa: PLC0415 - loads mcap

    refused = mcapfile.refusal(fmt, [])
    if refused:
        raise ConfigError(refused)
    stream = client.stream("/v1/ports/tap", {"ports": ports, **body})
    header = next(stream, None)
    if not isinstance(header, dict):
        raise SdrpeerError("the agent's tap sent no header")
    tapped = header["ports"]
    refused = mcapfile.refusal(fmt, [(p["ref"], p["type"]) for p in tapped])
    if refused:
        close = getattr(stream, "close", None)
        if close is not None:
            close()  # the tap's connections go with the stream
        raise PortToolError(refused)
    end: dict[str, Any] = {"end": "stream ended"}
    first = last = 0
    started = time.monotonic()
    with path.open("wb") as f:
        writer = mcapfile.RecordingWriter(f, fmt=fmt)
        channels = [writer.add_port(p["ref"], p["type"], p["fields"], p["robot"]) for p in tapped]
        try:
            for item in stream:
                if isinstance(item, dict):
                    end = item
                    break
                index, received, seq, value = item
                published = mcapfile.publish_ns(value, tapped[index]["fields"], received)
                data = writer.encode(channels[index], value)
                writer.write(channels[index], received, published, seq, data)
                first, last = first or received, received
        except KeyboardInterrupt:
            end = {"end": "interrupted"}
        finally:
            writer.finish()
    return {
        "frames": writer.messages,
        "bytes": writer.bytes,
        "ports": len(tapped),
        "seconds": time.monotonic() - started,
        "first_ns": first,
        "last_ns": last,
        "end": end,
    }


def cmd_record(args: argparse.Namespace) -> int:
    """Record OutPorts to an MCAP file (rtlog, `ros2 bag record`)."""
    body: dict[str, Any] = {"policy": _policy(args.policy) if args.policy else RECORD_POLICY}
    if args.count is not None:
        body["count"] = args.count
    if args.duration is not None:
        body["duration"] = args.duration
    done = record(client_for(args), args.ports, args.output, body, args.format)
    end = done["end"]
    print(
        f"recorded {done['frames']} frames ({done['bytes'] / 1e6:.1f} MB, format {args.format}) of "
        f"{done['ports']} port(s) in {done['seconds']:.1f} s to {args.output}"
        f" ({end.get('end')}; dropped {end.get('dropped', 0)})"
    )
    return 0


def _mapping(items: list[str]) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        src, sep, dst = item.partition("=")
        if not sep or not src or not dst:
            raise ConfigError(f"--map {item!r}: expected Instance.port=Other.port")
        out[src] = dst
    return out


def replay_chunks(
    path: Path, index: dict[str, int], speed: float, loop: bool, counts: dict[str, int]
) -> Iterator[bytes]:
    """The feed's body: `[index, value]` per recorded message (its bytes as recorded), each
    yielded at its recorded time scaled by `speed` (0: at once); `counts` counts them."""
    import msgpack  # noqa: PLC0415 - the parser stays light (sdrpeer.cli.main)

    from sdrpeer.ports.mcapfile import read_recording  # noqa: PLC0415 - loads mcap

    while True:
        first: int | None = None
        start = time.monotonic()
        for message in read_recording(path):
            if message.topic not in index:
                continue
            if speed > 0:
                first = message.log_time if first is None else first
                due = start + (message.log_time - first) / 1e9 / speed
                delay = due - time.monotonic()
                if delay > 0:
                    time.sleep(delay)  # the recorded pace
            counts[message.topic] = counts.get(message.topic, 0) + 1
            yield b"\x92" + msgpack.packb(index[message.topic]) + message.data
        if not loop:
            return


def replay(
    client: AgentClient, path: Path, mapping: dict[str, str], speed: float, loop: bool = False
) -> dict[str, Any]:
    """Feed the recording at `path` into ports (a channel into the port of its name, or the one
    `mapping` gives) at its recorded pace scaled by `speed` (0: at once); frames per channel,
    the agent's answer and the seconds it took."""
    from sdrpeer.ports import mcapfile  # noqa: PLC0415 - loads mcap

    if speed < 0:
        raise ConfigError(f"--speed: expected 0 (as fast as possible) or more, got {speed}")
    try:
        schemas = mcapfile.recorded_channels(path)
        if mcapfile.is_ros2(path):
            for _ in mcapfile.read_recording(path):
                pass  # every message decodes before any is sent
    except ValueError as e:  # its message names the file
        raise SdrpeerError(str(e)) from None
    except OSError as e:
        raise SdrpeerError(f"{path}: cannot read the recording: {e.strerror}") from None
    topics = sorted(schemas)
    unknown = sorted(set(mapping) - set(topics))
    if unknown:
        has = ", ".join(topics)
        raise ConfigError(f"--map: {', '.join(unknown)} not in {path} (it has {has})")
    targets = [mapping.get(t, t) for t in topics]
    unnamed = [t for t, to in zip(topics, targets, strict=True) if to.startswith("/")]
    if unnamed:
        raise ConfigError(
            f"{path}: {', '.join(unnamed)} name no port (a bag recorded by ROS): "
            f"give --map {unnamed[0]}=Instance.port"
        )
    index = {t: i for i, t in enumerate(topics)}
    types = ["" if schemas[t] == mcapfile.UNTYPED else schemas[t] for t in topics]
    query = urllib.parse.urlencode([*(("port", t) for t in targets), *(("type", t) for t in types)])
    counts: dict[str, int] = {}
    started = time.monotonic()
    answer = client.upload(
        f"/v1/ports/feed?{query}", replay_chunks(path, index, speed, loop, counts)
    )
    return {
        "channels": [
            {"topic": t, "to": to, "frames": counts.get(t, 0)}
            for t, to in zip(topics, targets, strict=True)
        ],
        "answer": answer,
        "seconds": time.monotonic() - started,
    }


def cmd_replay(args: argparse.Namespace) -> int:
    """Feed a recording back into ports, at its recorded pace scaled by --speed."""
    done = replay(client_for(args), args.file, _mapping(args.map), args.speed, args.loop)
    for channel in done["channels"]:
        print(f"{channel['topic']} -> {channel['to']}: {channel['frames']} frames")
    print(f"replayed {done['answer']['frames']} frames in {done['seconds']:.2f} s")
    return 0


def add_port_parsers(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
    client: argparse.ArgumentParser,
    as_json: argparse.ArgumentParser,
) -> None:
    """Register `sdrpeer port ...`."""
    port = sub.add_parser("port", help="port tools: list, connect, print, inject, record, replay")
    psub = port.add_subparsers(dest="port_command", required=True, metavar="ACTION")
    p = psub.add_parser("list", parents=[client, as_json], help="every port of every instance")
    p.add_argument("--here", action="store_true", help="only this agent's robot")
    p.set_defaults(func=cmd_list)
    policy = argparse.ArgumentParser(add_help=False)
    policy.add_argument(
        "--policy",
        action="append",
        default=[],
        metavar="K=V",
        help="connector policy, e.g. push=new",
    )
    p = psub.add_parser("connect", parents=[client, policy], help="connect A.out to B.in (rtcon)")
    p.add_argument("out", metavar="A.out")
    p.add_argument("inp", metavar="B.in")
    p.add_argument("--id", help="connection id (default A.out->B.in)")
    p.set_defaults(func=cmd_connect)
    p = psub.add_parser("disconnect", parents=[client], help="remove a run-time connection")
    p.add_argument("id_or_out", metavar="ID|A.out")
    p.add_argument("inp", metavar="B.in", nargs="?")
    p.set_defaults(func=cmd_disconnect)
    limits = argparse.ArgumentParser(add_help=False)
    limits.add_argument("--count", type=int, metavar="N", help="stop after N frames")
    limits.add_argument("--duration", type=float, metavar="S", help="stop after S seconds")
    p = psub.add_parser("print", parents=[client, limits, policy], help="print an OutPort's frames")
    p.add_argument("port", metavar="Instance.port")
    p.add_argument("--raw", action="store_true", help="typed values as arrays, not field maps")
    p.set_defaults(func=cmd_print)
    p = psub.add_parser("inject", parents=[client], help="send values to an InPort")
    p.add_argument("port", metavar="Instance.port")
    p.add_argument("value", metavar="VALUE", help="JSON or YAML; a typed port's: a map of fields")
    p.add_argument("--rate", type=float, metavar="HZ", help="values per second")
    p.add_argument("--count", type=int, default=1, metavar="N", help="how many (1)")
    p.set_defaults(func=cmd_inject)
    p = psub.add_parser("record", parents=[client, limits, policy], help="record to MCAP")
    p.add_argument("ports", nargs="+", metavar="Instance.port")
    p.add_argument("-o", "--output", type=Path, required=True, metavar="FILE.mcap")
    p.add_argument(
        "--format",
        choices=("sdrpeer", "ros2"),
        default="sdrpeer",
        help="sdrpeer: msgpack values (any port); ros2: rosbag2's CDR (ports of mapped types)",
    )
    p.set_defaults(func=cmd_record)
    p = psub.add_parser("replay", parents=[client], help="feed an MCAP recording into ports")
    p.add_argument("file", type=Path, metavar="FILE.mcap")
    p.add_argument("--speed", type=float, default=1.0, help="1 recorded pace, 0 at once")
    p.add_argument(
        "--map", action="append", default=[], metavar="A.port=B.port", help="replay into B.port"
    )
    p.add_argument("--loop", action="store_true", help="start over at the end, until Ctrl-C")
    p.set_defaults(func=cmd_replay)
