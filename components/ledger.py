"""A numbered source and a recording sink: what checks that a stream loses nothing.

How it works: `Sequencer` publishes 1, 2, 3, ... on `out` at `rate` Hz with `send` (it waits
while its connection is full, so with a `full: block` connector no number is dropped at the
source) and hands its count over when it moves. `Ledger` takes every number that arrives on
`inp` and appends it, one line each, to ``<dir>/<instance>-<pid>.seq`` (flushed per execution,
so a crash loses at most what its process had not written). Every instance of a moving Ledger
writes its own file; together the files say what was taken, lost (a number missing between 1
and the largest seen) and taken twice. `tools/bench_moves.py` reads them. `FrameLedger` is the
same for any value: it appends the msgpack encoding of every value it takes to
``<dir>/<instance>-<pid>.msgpack`` (`read_frames` cuts them apart again), which is how
`tools/bench_record.py` checks a replay byte for byte.
"""

from __future__ import annotations

import os
from typing import IO, Any

import msgpack

from sdrpeer.sdk import Component, InPort, OnInput, OutPort, Param, Periodic


class Sequencer(Component):
    """Publishes 1, 2, 3, ... on `out` at `rate` Hz, waiting when the connection is full."""

    execution = Periodic(param="rate")
    rate = Param(float, 200.0, "numbers per second")
    out = OutPort("the next number")

    def on_initialize(self) -> None:
        """Start from zero."""
        self.n = 0

    async def on_execute(self) -> None:
        """Publish the next number (backpressure: wait for room)."""
        self.n += 1
        await self.out.send(self.n)

    def on_snapshot(self) -> int:
        """The last number published."""
        return self.n

    def on_restore(self, state: Any) -> None:
        """Go on after the last number published."""
        if isinstance(state, int):
            self.n = state


class Ledger(Component):
    """Appends every number arriving on `inp` to its own file in `dir`."""

    execution = OnInput("inp")
    inp = InPort("numbers", policy={"push": "fifo", "buffer": 100_000, "full": "block"})
    dir = Param(str, "", "directory of the ledger files (empty: count only)")

    def on_initialize(self) -> None:
        """Open this instance's file."""
        self.taken = 0
        self._file: IO[str] | None = None
        if self.dir:
            os.makedirs(self.dir, exist_ok=True)
            name = f"{self.instance_name}-{os.getpid()}.seq"
            self._file = open(os.path.join(self.dir, name), "a", buffering=1 << 16)  # noqa: SIM115

    def on_execute(self) -> None:
        """Take everything queued; write it down."""
        lines = []
        while self.inp.qsize():
            lines.append(f"{self.inp.get_nowait()}\n")
        self.taken += len(lines)
        if self._file is not None and lines:
            self._file.write("".join(lines))
            self._file.flush()

    def on_finalize(self) -> None:
        """Close the file."""
        if self._file is not None:
            self._file.close()
            self._file = None


class FrameLedger(Component):
    """Appends the msgpack encoding of every value arriving on `inp` to its own file in `dir`."""

    execution = OnInput("inp")
    inp = InPort("any values", policy={"push": "fifo", "buffer": 100_000, "full": "block"})
    dir = Param(str, "", "directory of the frame files (empty: count only)")

    def on_initialize(self) -> None:
        """Open this instance's file."""
        self.taken = 0
        self._pack = msgpack.Packer().pack
        self._file: IO[bytes] | None = None
        if self.dir:
            os.makedirs(self.dir, exist_ok=True)
            name = f"{self.instance_name}-{os.getpid()}.msgpack"
            self._file = open(os.path.join(self.dir, name), "ab")  # noqa: SIM115

    def on_execute(self) -> None:
        """Take everything queued; write it down."""
        chunks = []
        while self.inp.qsize():
            chunks.append(self._pack(self.inp.get_nowait()))
        self.taken += len(chunks)
        if self._file is not None and chunks:
            self._file.write(b"".join(chunks))
            self._file.flush()

    def on_finalize(self) -> None:
        """Close the file."""
        if self._file is not None:
            self._file.close()
            self._file = None


def read_frames(directory: str) -> list[bytes]:
    """The msgpack encodings `FrameLedger` instances wrote to `directory`, file by file in name
    order, each file in the order its values were taken."""
    out: list[bytes] = []
    for name in sorted(os.listdir(directory)):
        if not name.endswith(".msgpack"):
            continue
        with open(os.path.join(directory, name), "rb") as f:
            data = f.read()
        unpacker = msgpack.Unpacker(raw=False, max_buffer_size=max(len(data), 1 << 20))
        unpacker.feed(data)
        start = 0
        for _ in unpacker:
            end = unpacker.tell()
            out.append(data[start:end])
            start = end
    return out


SYSTEM = """\
name: moves
components:
  - name: Sequencer
    target: components.ledger:Sequencer
    params: {{rate: {rate}}}
    pin: robot-1
  - name: Ledger
    target: components.ledger:Ledger
    params: {{dir: '{dir}'}}
    prefer: [robot-2]
{standby}connections:
  - {{from: Sequencer.out, to: Ledger.inp, policy: {{push: fifo, buffer: 256, full: block}}}}
"""


def ledger_system(directory: str, rate: float = 200.0, *, standby: bool = False) -> str:
    """A system file: a Sequencer pinned to robot-1 feeding a Ledger (first on robot-2) over a
    fifo/block connection; with `standby`, the Ledger has a hot standby on another robot."""
    extra = "    standby: {other_robots: 1, mode: hot}\n" if standby else ""
    return SYSTEM.format(rate=rate, dir=directory, standby=extra)


def read_ledgers(directory: str) -> dict[str, Any]:
    """What the ledger files of `directory` say: taken, distinct, highest, lost, duplicates."""
    seen: list[int] = []
    files = 0
    for name in sorted(os.listdir(directory)):
        if not name.endswith(".seq"):
            continue
        files += 1
        with open(os.path.join(directory, name)) as f:
            seen += [int(line) for line in f if line.strip().isdigit()]
    distinct = set(seen)
    top = max(distinct, default=0)
    return {
        "files": files,
        "taken": len(seen),
        "distinct": len(distinct),
        "highest": top,
        "lost": top - len(distinct),
        "duplicates": len(seen) - len(distinct),
    }
