"""Data-plane benchmark: sdrpeer streams against pyzmq and plain sockets, between two processes.

Usage: python tools/bench_dataplane.py [--json out.json] [--quick] [--reps N] [--only SECTIONS]

How it works: every measurement spawns its peer as a subprocess (tools/dataplane_peers.py, one
role each: its stdout carries one JSON line with its address, then one with its result), so
sender and receiver are separate processes on this machine, as two component hosts would be.
- throughput: from the sender's first send (connection set up) to the receiver's last frame,
  both read from CLOCK_MONOTONIC (`time.perf_counter`, one clock for both processes); 100-byte
  frames in frames/s, 1 MB frames in MB/s (10^6 bytes);
- CPU (1 MB acked rows): `time.process_time` of the sender while sending plus that of the
  receiver while receiving, per GB carried, and the MB/s all this machine's cores could carry
  at that cost (the ceiling when both ends share the cores, as here);
- round trip: the sender times each 100-byte ping until its pong arrives; p50 and p99 in µs.
  `sdrpeer_tcp` is a data-port round trip (an OutPort's connection there, another back);
  `sdrpeer_service` a service call (sdrpeer.sdk.services: `ServiceCaller.call("echo", 100 B)`
  to a provided service in the peer, request and reply on one socket), against which the
  target compares it (both over TCP without data keys).
- loss (issue 17's silent-loss case): 5,000 frames of 100 B written as fast as an OutPort's
  `write` does, with the SDK's default policy (all, 8, overwrite) at both ends, into a consumer
  that takes one frame per event-loop turn (an OnInput component): how many it took, how many
  the sender counted as dropped in its own queue and as told by the receiver's acknowledgements,
  and `silent`, what nobody counted at the sender (the target: 0).
The 100 B target against pyzmq is judged twice: frames counted at the socket (`sdrpeer_tcp`),
and the path a component sees (`sdrpeer_tcp_acked`: into the InPort, taken, acknowledged), since
pyzmq's frames are delivered to Python code.
  `asyncio_raw` (a bare asyncio Protocol echo, no framing at all) is the floor of any design
  on asyncio's event loop, shown for scale.
Contenders: sdrpeer (Connection -> DataServer; policy fifo + block; over TCP, over a Unix socket
with the shared-memory ring turned off (`sdrpeer_unix`), and as a same-robot connection runs by
default (`sdrpeer_shm`: a Unix socket, big values through the ring; 1 MB rows only, since small
values never take the ring), and over TCP into the SDK's InPort with a consumer taking every
frame (`sdrpeer_tcp_acked`: the stream a component gets, acknowledged, the sender keeping its
unacknowledged frames for replay; `sdrpeer_tcp_inport`: the same without acknowledgements; the
other sdrpeer rows count frames at the socket), pyzmq
(PUSH/PULL, REQ/REP; blocking sockets), a plain length-prefixed socket loop (one sendall per
frame; the receiver parses frames out of a recv_into buffer and makes each a bytes object) and
the same loop sending frames coalesced by 256. `sdrpeer_tcp_acked_enc` is `sdrpeer_tcp_acked`
between two ends holding a data key (a random one per run, given to the receiver process as
SDRPEER_DATA_KEYS, as an agent gives its hosts): authenticated and AES-GCM encrypted, the
default between robots. `sdrpeer_tcp_acked_typed` is `sdrpeer_tcp_acked` with a typed port at
both ends (sdrpeer.sdk.typed): a 100-byte `Pose` written through an `OutPortRuntime` (checked
and encoded for every frame) and decoded into a `Pose` by the InPort for its consumer;
`zmq_typed` carries the same Pose over pyzmq as a developer would by hand (its fields packed as
a msgpack array, made back into a Pose): the typed target is judged against both. Every
cell is the median of --reps runs; the contenders run interleaved within each rep, and a
target's ratio is the median over reps of the ratio measured within one rep (the load of this
shared machine shifts between reps).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

import msgpack
import zmq
from dataplane_peers import LEN, Peer, payload, typed_pose
from dataplane_pings import SMALL, asyncio_pings, plain_pings, sdr_pings, svc_pings, zmq_pings

from sdrpeer.dataplane import Connection
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.dataplane.shm import DEFAULT_SIZE
from sdrpeer.dataplane.testing import make_policy
from sdrpeer.sdk.policy import ConnectorPolicy
from sdrpeer.sdk.ports import OutPortRuntime
from sdrpeer.sdk.typed import message_type

BIG = 1_000_000
# (target name, contender, baseline, minimum ratio contender/baseline)
THROUGHPUT_TARGETS = [
    ("100 B at the socket >= 1.0x pyzmq", ("small", "sdrpeer_tcp"), ("small", "zmq"), 1.0),
    (
        "100 B into the InPort (acked) >= 1.0x pyzmq",
        ("small", "sdrpeer_tcp_acked"),
        ("small", "zmq"),
        1.0,
    ),
    (
        "typed 100 B into the InPort (acked) >= 1.0x pyzmq",
        ("small", "sdrpeer_tcp_acked_typed"),
        ("small", "zmq"),
        1.0,
    ),
    (
        "typed 100 B into the InPort (acked) >= 1.0x pyzmq typed by hand",
        ("small", "sdrpeer_tcp_acked_typed"),
        ("small", "zmq_typed"),
        1.0,
    ),
    ("1 MB TCP >= 0.8x plain TCP", ("big", "sdrpeer_tcp"), ("big", "plain_tcp"), 0.8),
    ("1 MB same-robot >= 1.5x plain TCP", ("big", "sdrpeer_shm"), ("big", "plain_tcp"), 1.5),
    (
        "100 B encrypted >= 0.8x unencrypted (acked, into the InPort)",
        ("small", "sdrpeer_tcp_acked_enc"),
        ("small", "sdrpeer_tcp_acked"),
        0.8,
    ),
    (
        "1 MB encrypted >= 0.7x unencrypted (acked, into the InPort)",
        ("big", "sdrpeer_tcp_acked_enc"),
        ("big", "sdrpeer_tcp_acked"),
        0.7,
    ),
]
RTT_TARGET = 1.3  # sdrpeer p50 <= 1.3x plain socket p50
SERVICE_TARGET = 1.5  # a service call's p50 <= 1.5x the data-port round trip's p50


# ---- senders (the parent process) ---------------------------------------------------------


async def _sdr_send(
    to: str,
    n: int,
    size: int,
    *,
    shm: bool,
    acks: bool = True,
    keys: list[bytes] | None = None,
    typed: bool = False,
) -> tuple[float, float]:
    """(perf_counter at the first send, CPU seconds this process spent sending). `typed`: a
    100-byte Pose written through a typed OutPort (encoded for every frame, type told)."""
    buffer = 4096 if size <= 1024 else 4
    policy = make_policy("fifo", buffer, "block")
    size_shm = DEFAULT_SIZE if shm else 0
    auth = DataAuth(keys) if keys else None
    pose = typed_pose() if typed else None
    port = OutPortRuntime("out", port_type=None if pose is None else type(pose))
    conn = Connection(
        "bench", to, "sink", "bench.out", policy, shm_size=size_shm, auth=auth, type_id=port.type_id
    )
    if not acks:
        conn.window = None  # the receiver's InPort would acknowledge: do not ask it to
    conn.start()
    async with asyncio.timeout(10):
        await conn.wait_connected()
    value, offer, drain = payload(size), conn.offer, conn.drain
    start, cpu = time.perf_counter(), time.process_time()
    if pose is not None:  # as a component's OutPort.send does: wait for room, then write
        port.attach(conn)
        write = port.write
        for _ in range(n):
            if conn.pending >= buffer:  # full: wait for room (what `send` would await)
                await drain()
            write(pose)
    else:
        for _ in range(n):
            if not offer(value):
                await drain()
                offer(value)
    await conn.close(linger=60)
    return start, time.process_time() - cpu


def sdr_throughput(kind: str, n: int, size: int) -> float:
    """Seconds the sdrpeer receiver took for n frames of `size` bytes (see `sdr_run`)."""
    return sdr_run(kind, n, size)[0]


def sdr_run(kind: str, n: int, size: int) -> tuple[float, float | None]:
    """(Seconds the sdrpeer receiver took for n frames of `size` bytes, CPU seconds both
    processes spent on them (acked kinds; else None)); kind tcp, unix (the
    socket alone), shm (a Unix socket with the shared-memory ring, the default), tcp_acked
    (into the SDK's InPort, taken by a consumer: an acknowledged stream), tcp_inport (the
    same without acknowledgements: what the acks cost is the difference) or tcp_acked_enc
    (tcp_acked between two hosts holding a data key: authenticated and encrypted)."""
    with tempfile.TemporaryDirectory() as tmp:
        role = "sdr-inport" if kind.startswith(("tcp_acked", "tcp_inport")) else "sdr-sink"
        role += "-typed" if kind.endswith("_typed") else ""
        keys = [os.urandom(32)] if kind.endswith("_enc") else None
        peer = Peer(role, n, os.path.join(tmp, "rx.sock"), keys=keys)
        scheme = "unix" if kind in ("unix", "shm") else "tcp"
        to = f"{scheme}://{peer.addresses[scheme]}"
        acks = kind != "tcp_inport"
        typed = kind.endswith("_typed")
        send = _sdr_send(to, n, size, shm=kind == "shm", acks=acks, keys=keys, typed=typed)
        start, sender_cpu = asyncio.run(send)
        result = peer.finish()
        cpu = sender_cpu + float(result["cpu"]) if "cpu" in result else None
        return float(result["end"]) - start, cpu


LOSS_FRAMES = 5000
"""Frames of the silent-loss case (issue 17: OpenRTM's listener got all 5,000)."""


async def _sdr_burst(to: str, n: int) -> dict[str, int]:
    """n frames of 100 B written as fast as a component's OutPort.write does (no waiting for
    room), with the SDK's default policy; what the sender counted once all was handled."""
    conn = Connection("loss", to, "sink", "bench.out", ConnectorPolicy(), given={})
    conn.start()
    async with asyncio.timeout(10):
        await conn.wait_connected()
    value = payload(SMALL)
    for k in range(n):
        conn.offer(value)
        if k % 64 == 63:
            await asyncio.sleep(0)  # a producer's loop iteration
    async with asyncio.timeout(30):
        while conn.pending or conn.unacked:  # noqa: ASYNC110 - acks set no event to wait on
            await asyncio.sleep(0.01)
    counted = {"dropped": conn.dropped, "dropped_remote": conn.dropped_remote}
    await conn.close()
    return counted


def loss_run(n: int = LOSS_FRAMES) -> dict[str, int]:
    """The silent-loss case between two processes: n frames into an InPort with the SDK's
    defaults (all, 8, overwrite) and a consumer that takes one frame per event-loop turn.
    `silent` is what neither the consumer took nor the sender counted as dropped."""
    with tempfile.TemporaryDirectory() as tmp:
        peer = Peer("sdr-consumer", 0, os.path.join(tmp, "rx.sock"))
        sent = asyncio.run(_sdr_burst(f"tcp://{peer.addresses['tcp']}", n))
        got = peer.finish()
    counted = sent["dropped"] + sent["dropped_remote"]
    return {
        "frames": n,
        "taken": int(got["taken"]),
        "dropped_at_sender": sent["dropped"],
        "dropped_at_receiver_told": sent["dropped_remote"],
        "dropped_at_receiver_counted": int(got["dropped"]),
        "silent": n - int(got["taken"]) - counted,
    }


def plain_throughput(n: int, size: int, batch: int = 1) -> float:
    """Seconds the plain socket receiver took; `batch` frames per sendall."""
    peer = Peer("plain-sink", n)
    sock = socket.create_connection(peer.tcp())
    frame = LEN.pack(size) + payload(size)
    chunk = frame * batch
    start = time.perf_counter()
    for _ in range(n // batch):
        sock.sendall(chunk)
    for _ in range(n % batch):
        sock.sendall(frame)
    seconds = float(peer.finish()["end"]) - start
    sock.close()
    return seconds


def zmq_throughput(n: int, size: int, *, typed: bool = False) -> float:
    """Seconds the pyzmq PULL receiver took. `typed`: each frame the same 100-byte Pose as
    the typed sdrpeer row, packed as a msgpack array of its fields and made back into a Pose
    (what a developer does to send typed messages over pyzmq)."""
    peer = Peer("zmq-pull-typed" if typed else "zmq-pull", n)
    ctx = zmq.Context()
    sock = ctx.socket(zmq.PUSH)
    sock.connect(f"tcp://{peer.addresses['tcp']}")
    value = payload(size)
    start = time.perf_counter()
    if typed:
        pose = typed_pose()
        flat = message_type(type(pose)).flat  # type: ignore[union-attr]
        packb = msgpack.packb
        for _ in range(n):
            sock.send(packb(flat(pose)))
    else:
        for _ in range(n):
            sock.send(value)
    seconds = float(peer.finish()["end"]) - start
    sock.close(linger=0)
    ctx.term()
    return seconds


# ---- the report ---------------------------------------------------------------------------


def measure(
    quick: bool, reps: int, log: Callable[[str], None], only: str = "small,big,rtt,loss"
) -> dict[str, Any]:
    """Every figure (or the sections in `only`), medians of `reps` runs."""
    n_small, n_big, m = (20_000, 20, 300) if quick else (300_000, 500, 5000)
    small: dict[str, Callable[[], float]] = {
        "sdrpeer_tcp": lambda: sdr_throughput("tcp", n_small, SMALL),
        "sdrpeer_tcp_inport": lambda: sdr_throughput("tcp_inport", n_small, SMALL),
        "sdrpeer_tcp_acked": lambda: sdr_throughput("tcp_acked", n_small, SMALL),
        "sdrpeer_tcp_acked_enc": lambda: sdr_throughput("tcp_acked_enc", n_small, SMALL),
        "sdrpeer_tcp_acked_typed": lambda: sdr_throughput("tcp_acked_typed", n_small, SMALL),
        "sdrpeer_unix": lambda: sdr_throughput("unix", n_small, SMALL),
        "zmq": lambda: zmq_throughput(n_small, SMALL),
        "zmq_typed": lambda: zmq_throughput(n_small, SMALL, typed=True),
        "plain_tcp": lambda: plain_throughput(n_small, SMALL),
        "plain_tcp_coalesced": lambda: plain_throughput(n_small, SMALL, batch=256),
    }
    cpu_runs: dict[str, list[float]] = {}

    def counted(kind: str) -> float:
        """Seconds of one big run, its CPU seconds per GB (both ends) kept in cpu_runs."""
        seconds, cpu = sdr_run(kind, n_big, BIG)
        assert cpu is not None
        cpu_runs.setdefault(f"sdrpeer_{kind}", []).append(cpu / (n_big * BIG / 1e9))
        return seconds

    big: dict[str, Callable[[], float]] = {
        "sdrpeer_tcp": lambda: sdr_throughput("tcp", n_big, BIG),
        "sdrpeer_tcp_inport": lambda: sdr_throughput("tcp_inport", n_big, BIG),
        "sdrpeer_tcp_acked": lambda: counted("tcp_acked"),
        "sdrpeer_tcp_acked_enc": lambda: counted("tcp_acked_enc"),
        "sdrpeer_unix": lambda: sdr_throughput("unix", n_big, BIG),
        "sdrpeer_shm": lambda: sdr_throughput("shm", n_big, BIG),
        "plain_tcp": lambda: plain_throughput(n_big, BIG),
        "zmq": lambda: zmq_throughput(n_big, BIG),
    }
    pings: dict[str, Callable[[], list[float]]] = {
        "sdrpeer_tcp": lambda: asyncio.run(sdr_pings(m)),
        "sdrpeer_service": lambda: asyncio.run(svc_pings(m)),
        "plain_tcp": lambda: plain_pings(m),
        "zmq": lambda: zmq_pings(m),
        "asyncio_raw": lambda: asyncio.run(asyncio_pings(m)),
    }
    out: dict[str, Any] = {
        "quick": quick,
        "reps": reps,
        "cores": os.cpu_count(),
        "small": {},
        "big": {},
        "rtt": {},
        "cpu_per_gb": {},
        "loss": [],
    }
    runs: dict[tuple[str, str], list[float]] = {}
    for rep in range(reps):  # interleaved, so slow phases of the machine hit every contender
        log(f"rep {rep + 1}/{reps}")
        if "small" not in only:
            small = {}
        if "big" not in only:
            big = {}
        if "rtt" not in only:
            pings = {}
        for name, run in small.items():
            runs.setdefault(("small", name), []).append(n_small / run())
        for name, run in big.items():
            runs.setdefault(("big", name), []).append(n_big * BIG / 1e6 / run())
        if "loss" in only:
            out["loss"].append(loss_run())
        for name, ping in pings.items():
            times = sorted(ping()[m // 10 :])  # the first tenth warms up
            runs.setdefault(("p50", name), []).append(times[len(times) // 2] * 1e6)
            runs.setdefault(("p99", name), []).append(times[int(len(times) * 0.99)] * 1e6)
    for (section, name), values in runs.items():
        if section in ("small", "big"):
            out[section][name] = {"median": statistics.median(values), "runs": values}
        else:
            cell = out["rtt"].setdefault(name, {})
            cell[f"{section}_us"] = statistics.median(values)
            cell[f"{section}_runs"] = values

    for name, values in cpu_runs.items():
        ceiling = (out["cores"] or 1) / statistics.median(values) * 1e3  # MB/s, cores all busy
        out["cpu_per_gb"][name] = {
            "median": statistics.median(values),
            "runs": values,
            "ceiling_mb_s": ceiling,
        }

    def paired(a: tuple[str, str], b: tuple[str, str]) -> float:
        """Median over reps of the ratio within each rep (the machine's load shifts cancel)."""
        return statistics.median(x / y for x, y in zip(runs[a], runs[b], strict=True))

    targets = []
    for label, (sec, name), (bsec, base), minimum in THROUGHPUT_TARGETS:
        if sec in only:
            ratio = paired((sec, name), (bsec, base))
            targets.append({"target": label, "ratio": ratio, "met": ratio >= minimum})
    if "rtt" in only:
        ratio = paired(("p50", "sdrpeer_tcp"), ("p50", "plain_tcp"))
        met = ratio <= RTT_TARGET
        targets.append({"target": "RTT p50 <= 1.3x plain", "ratio": ratio, "met": met})
        ratio = paired(("p50", "sdrpeer_service"), ("p50", "sdrpeer_tcp"))
        met = ratio <= SERVICE_TARGET
        label = "service call p50 <= 1.5x data-port RTT"
        targets.append({"target": label, "ratio": ratio, "met": met})
    if out["loss"]:
        silent = max(r["silent"] for r in out["loss"])
        targets.append(
            {
                "target": "default policies lose nothing silently",
                "silent": silent,
                "met": not silent,
            }
        )
    out["targets"] = targets
    return out


def render(out: dict[str, Any]) -> str:
    """The figures as a text table."""
    lines = [f"100-byte frames, frames/s (median of {out['reps']})"]
    lines += [f"  {k:<22} {v['median']:>12,.0f}" for k, v in out["small"].items()]
    lines.append("1 MB frames, MB/s")
    lines += [f"  {k:<22} {v['median']:>12,.0f}" for k, v in out["big"].items()]
    if out["cpu_per_gb"]:
        lines.append(
            "1 MB, CPU seconds per GB of both ends (sender + receiver) and the most MB/s "
            f"{out['cores']} cores could carry at that cost"
        )
        lines += [
            f"  {k:<22} {v['median']:>9.3f} s/GB  ceiling {v['ceiling_mb_s']:>7,.0f} MB/s"
            for k, v in out["cpu_per_gb"].items()
        ]
    lines.append("100-byte round trip, µs        p50      p99")
    lines += [f"  {k:<22} {v['p50_us']:>9.1f} {v['p99_us']:>8.1f}" for k, v in out["rtt"].items()]
    if out["loss"]:
        lines.append(
            f"{LOSS_FRAMES:,} frames of 100 B, fast producer into a default InPort (all, 8, "
            "overwrite), one frame taken per loop turn"
        )
        lines.append("  taken  dropped@sender  dropped@receiver (told / counted there)  silent")
        lines += [
            f"  {r['taken']:>5}  {r['dropped_at_sender']:>14}  {r['dropped_at_receiver_told']:>16}"
            f" / {r['dropped_at_receiver_counted']:<21}  {r['silent']:>6}"
            for r in out["loss"]
        ]
    lines.append("Targets (median of per-rep ratios)")
    for t in out["targets"]:
        verdict = "met" if t["met"] else "MISSED"
        if "ratio" in t:
            lines.append(f"  {t['target']:<44} {t['ratio']:>6.2f}x  {verdict}")
        else:
            lines.append(f"  {t['target']:<44} {t['silent']:>6} silent  {verdict}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark."""
    if argv is None:
        argv = sys.argv[1:]
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", metavar="PATH", help="also write every figure to this file")
    parser.add_argument("--quick", action="store_true", help="small counts, one rep: a smoke test")
    parser.add_argument("--reps", type=int, help="runs per cell (default 5, quick 1)")
    parser.add_argument("--only", default="small,big,rtt,loss", help="sections: small,big,rtt,loss")
    args = parser.parse_args(argv)
    reps = args.reps or (1 if args.quick else 5)
    out = measure(
        args.quick, reps, lambda text: print(text, file=sys.stderr, flush=True), args.only
    )
    print(render(out))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
