"""Drive a real host process the way the agent does: a socket pair, `pass_fds`, msgpack maps.

How it works: `HostProc.spawn` creates a Unix socket pair, starts `python -m sdrpeer.host TARGET`
with the child's end inherited as `SDRPEER_CONTROL_FD` (plus the other variables of
docs/protocol.md) and its stderr in a log file, and keeps our end. `recv` reads the next report
with a deadline, stamping each with its arrival time (`_rx`, time.time()) and keeping every one
in `seen`; `wait_for` skips reports until one matches; `command` sends a command with a fresh id
and returns its reply, leaving the reports that came before it for later waits. Every wait is
bounded; `HostPool.close_all` kills whatever is still running. Run as a script
(`python -m tests.hostctl [TARGET]`) it measures spawn-to-INACTIVE and idle RSS.
"""

from __future__ import annotations

import itertools
import os
import select
import socket
import subprocess
import sys
import time
from collections import deque
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack

ROOT = Path(__file__).resolve().parent.parent
Msg = dict[str, Any]


def rss_kb(pid: int) -> int:
    """Resident set size of `pid` in KiB (Linux /proc)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError(f"no VmRSS for pid {pid}")


class HostProc:
    """One host subprocess and our end of its control channel."""

    def __init__(self, proc: subprocess.Popen[bytes], sock: socket.socket, log: Path) -> None:
        self.proc = proc
        self.sock = sock
        self.log = log
        self.spawned = time.monotonic()
        self.seen: list[Msg] = []
        self._pending: deque[Msg] = deque()
        self._unpacker = msgpack.Unpacker(raw=False)
        self._ids = itertools.count(1)
        self.eof = False

    @classmethod
    def spawn(
        cls,
        target: str,
        *args: str,
        name: str = "h",
        run_dir: Path,
        env: dict[str, str] | None = None,
        control: bool = True,
        module: str = "sdrpeer.host",
    ) -> HostProc:
        """Start a host for `target` as the agent would (`module`: the host's module, e.g.
        `sdrpeer.ros2.host` or the openrtm launcher's `sdrpeer.openrtm`)."""
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        full_env = {k: v for k, v in os.environ.items() if not k.startswith("SDRPEER_")}
        full_env["PYTHONPATH"] = str(ROOT)
        full_env.update(
            SDRPEER_INSTANCE=name, SDRPEER_DATA_HOST="127.0.0.1", SDRPEER_RUN_DIR=str(run_dir)
        )
        if control:
            full_env["SDRPEER_CONTROL_FD"] = str(theirs.fileno())
        full_env.update(env or {})
        log = run_dir / f"{name}.log"
        with open(log, "wb") as err:
            proc = subprocess.Popen(
                [sys.executable, "-m", module, target, *args],
                pass_fds=[theirs.fileno()] if control else [],
                stdin=subprocess.DEVNULL,
                stdout=err,
                stderr=err,
                env=full_env,
                cwd=ROOT,
            )
        theirs.close()
        return cls(proc, ours, log)

    def log_text(self) -> str:
        """What the host wrote to stderr so far."""
        return self.log.read_text(errors="replace")

    def send(self, msg: Msg) -> None:
        """Write one map to the host."""
        self.sock.sendall(msgpack.packb(msg, use_bin_type=True))

    def recv(self, timeout: float) -> Msg | None:
        """The next report, or None if none came within `timeout` seconds (or the host closed)."""
        deadline = time.monotonic() + timeout
        while not self._pending and not self.eof:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self.sock], [], [], left)[0]:
                return None
            data = self.sock.recv(1 << 16)
            if not data:
                self.eof = True
                break
            now = time.time()
            self._unpacker.feed(data)
            for msg in self._unpacker:
                msg["_rx"] = now
                self.seen.append(msg)
                self._pending.append(msg)
        return self._pending.popleft() if self._pending else None

    def wait_for(self, match: Callable[[Msg], bool], timeout: float = 5.0, what: str = "") -> Msg:
        """Skip reports until one matches; AssertionError with the last few seen if none does."""
        deadline = time.monotonic() + timeout
        while True:
            msg = self.recv(max(0.0, deadline - time.monotonic()))
            if msg is not None and match(msg):
                return msg
            if msg is None:
                tail = [{k: v for k, v in m.items() if k != "_rx"} for m in self.seen[-5:]]
                raise AssertionError(
                    f"no {what or 'matching report'} within {timeout} s (eof={self.eof}); "
                    f"last seen {tail}; log:\n{self.log_text()[-2000:]}"
                )

    def wait_t(self, t: str, timeout: float = 5.0) -> Msg:
        """The next report of type `t`."""
        return self.wait_for(lambda m: m["t"] == t, timeout, t)

    def wait_state(self, state: str, timeout: float = 5.0) -> Msg:
        """The next `state` report saying `state`."""
        return self.wait_for(
            lambda m: m["t"] == "state" and m["state"] == state, timeout, f"state {state}"
        )

    def command(self, t: str, timeout: float = 5.0, **fields: Any) -> Msg:
        """Send command `t` and return its reply."""
        ident = next(self._ids)
        self.send({"t": t, "id": ident, **fields})
        skipped: list[Msg] = []

        def is_reply(m: Msg) -> bool:
            if m["t"] == "reply" and m["id"] == ident:
                return True
            skipped.append(m)
            return False

        reply = self.wait_for(is_reply, timeout, f"reply to {t}")
        self._pending.extendleft(reversed(skipped))  # later waits still see them
        return reply

    def wait_exit(self, timeout: float = 5.0) -> int:
        """The exit code (AssertionError if the host is still running after `timeout`)."""
        try:
            return self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            raise AssertionError(f"host still running; log:\n{self.log_text()[-2000:]}") from None

    def kill(self) -> None:
        """Kill the host if it still runs and close our socket."""
        if self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(5)
        self.sock.close()


class HostPool:
    """Hosts started by one test; `close_all` kills the leftovers."""

    def __init__(self, run_dir: Path) -> None:
        self.run_dir = run_dir
        self.hosts: list[HostProc] = []

    def spawn(self, target: str, *args: str, name: str = "h", **kw: Any) -> HostProc:
        """Start a host (see HostProc.spawn)."""
        host = HostProc.spawn(target, *args, name=name, run_dir=self.run_dir, **kw)
        self.hosts.append(host)
        return host

    def ready(self, target: str, *args: str, name: str = "h", **kw: Any) -> tuple[HostProc, Msg]:
        """Start a host and wait for hello and `state INACTIVE`; returns it and its hello."""
        host = self.spawn(target, *args, name=name, **kw)
        hello = host.wait_t("hello", 10.0)
        host.wait_state("INACTIVE", 10.0)
        return host, hello

    def close_all(self) -> None:
        """Kill every host still running."""
        for host in self.hosts:
            host.kill()


def measure(target: str, run_dir: Path, idle: float = 1.0) -> tuple[float, int]:
    """(seconds from spawn to `state INACTIVE`, RSS in KiB after `idle` seconds) of one host."""
    host = HostProc.spawn(target, run_dir=run_dir)
    try:
        host.wait_state("INACTIVE", 10.0)
        startup = time.monotonic() - host.spawned
        time.sleep(idle)
        return startup, rss_kb(host.proc.pid)
    finally:
        host.command("exit")
        host.wait_exit()
        host.kill()


if __name__ == "__main__":
    import tempfile

    target = sys.argv[1] if len(sys.argv) > 1 else "tests.components_fixture:Counter"
    with tempfile.TemporaryDirectory() as tmp:
        runs = [measure(target, Path(tmp)) for _ in range(5)]
    starts = sorted(s for s, _ in runs)
    print(
        f"{target}: spawn to INACTIVE median {starts[2] * 1000:.0f} ms "
        f"(min {starts[0] * 1000:.0f}, max {starts[-1] * 1000:.0f}); "
        f"idle RSS {max(r for _, r in runs) / 1024:.1f} MiB (max of 5)"
    )
