"""A tiny stand-in for a component host: speaks the control channel of docs/protocol.md.

How it works: started by a supervisor (launcher `exec`, argv `python tests/fake_host.py
[--mode M,...]`), it finds its socket in $SDRPEER_CONTROL_FD, binds a real TCP listener (so its
data address is real), sends `hello` and `state INACTIVE`, answers every command, sends a
`heartbeat` every --heartbeat seconds and exits on `exit` or when the agent goes away (EOF).
Every command it receives is printed to stderr (the instance log) as `fake-host: got T`.
Modes make it misbehave: ignore_exit, ignore_term (SIGTERM too), no_reply, refuse, garbage,
oversize, no_hello, error_init, crash_on_activate.
"""

from __future__ import annotations

import argparse
import os
import select
import signal
import socket
import sys
import time
from typing import Any

import msgpack

TRANSITIONS = {"activate": "ACTIVE", "deactivate": "INACTIVE", "reset": "INACTIVE"}


def main() -> int:
    """Run the fake host until exit or EOF."""
    parser = argparse.ArgumentParser()
    parser.add_argument("--mode", default="")
    parser.add_argument("--heartbeat", type=float, default=0.5)
    args = parser.parse_args()
    modes = set(filter(None, args.mode.split(",")))
    if "ignore_term" in modes:
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sock = socket.socket(fileno=int(os.environ["SDRPEER_CONTROL_FD"]))
    listener = socket.create_server((os.environ.get("SDRPEER_DATA_HOST", "127.0.0.1"), 0))
    host, port = listener.getsockname()[:2]
    run_dir = os.environ.get("SDRPEER_RUN_DIR", "/tmp")
    conns: dict[str, str] = {}

    def send(msg: dict[str, Any]) -> None:
        sock.sendall(msgpack.packb(msg, use_bin_type=True))

    def state(name: str, error: str | None = None) -> None:
        send({"t": "state", "state": name, "ts": time.time(), "error": error})

    print(
        f"fake-host: start {os.environ.get('SDRPEER_INSTANCE')} modes={sorted(modes)}",
        file=sys.stderr,
        flush=True,
    )
    if "no_hello" not in modes:
        send({
            "t": "hello", "protocol": 1, "pid": os.getpid(), "component": "Fake",
            "ports": {"in": ["inp"], "out": ["out"]}, "params": {},
            "data": {"tcp": f"{host}:{port}", "unix": f"{run_dir}/data.sock"},
        })  # fmt: skip
        state("CREATED")
        if "error_init" in modes:
            state("ERROR", "on_initialize failed: fake")
        else:
            state("INACTIVE")
    if "garbage" in modes:
        send(["not", "a", "map"])  # type: ignore[arg-type]
    if "oversize" in modes:
        send({"t": "fault", "kind": "big", "detail": "x" * (1 << 20)})
    unpacker = msgpack.Unpacker(raw=False)
    next_beat = time.monotonic() + args.heartbeat
    while True:
        ready, _, _ = select.select([sock], [], [], max(0.0, next_beat - time.monotonic()))
        if not ready:
            ports = {"out": {"frames_out": 1, "bytes_out": 10}, "inp": {"frames_in": 2}}
            send({"t": "heartbeat", "ts": time.time(), "ports": ports})
            next_beat = time.monotonic() + args.heartbeat
            continue
        data = sock.recv(65536)
        if not data:
            print("fake-host: EOF", file=sys.stderr, flush=True)
            return 0
        unpacker.feed(data)
        for msg in unpacker:
            t = msg.get("t")
            print(f"fake-host: got {t} {msg}", file=sys.stderr, flush=True)
            if "no_reply" in modes or (t == "exit" and "ignore_exit" in modes):
                continue
            if t == "activate" and "crash_on_activate" in modes:
                os._exit(3)
            if t == "activate" and "slow_activate" in modes:
                time.sleep(1.5)  # a long on_activated: no heartbeat meanwhile
            ok = "refuse" not in modes and t in {*TRANSITIONS, "exit", "set_params", "connect",
                                                  "disconnect", "repoint"}  # fmt: skip
            if ok and t == "connect":
                conns[msg["conn"]["id"]] = msg["conn"]["to"]
            if ok and t == "disconnect":
                ok = conns.pop(msg["conn_id"], None) is not None
            send({"t": "reply", "id": msg["id"], "ok": ok, "error": None if ok else "no"})
            if ok and t in TRANSITIONS:
                state(TRANSITIONS[t])
            if ok and t == "exit":
                state("FINALIZED")
                return 0


if __name__ == "__main__":
    sys.exit(main())
