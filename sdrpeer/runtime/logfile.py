"""Reading instance logs: the last N lines, and following new output (for the API).

How it works: `tail` reads backwards from the end in blocks until it has N line breaks or
`max_bytes`, so a huge log costs only what is shown. `Follower` remembers an offset and returns
whatever was appended since (at most `max_bytes` per call); a truncated or replaced file starts
over from its beginning.
"""

from __future__ import annotations

import os
from pathlib import Path

MAX_TAIL_LINES = 10_000
MAX_BYTES = 1 << 20
_BLOCK = 8192


def tail(path: Path, lines: int, max_bytes: int = MAX_BYTES) -> bytes:
    """The last `lines` lines of a file (b"" if it does not exist), at most `max_bytes`."""
    try:
        f = path.open("rb")
    except FileNotFoundError:
        return b""
    with f:
        end = f.seek(0, os.SEEK_END)
        pos, data = end, b""
        while pos > 0 and data.count(b"\n") <= lines and len(data) < max_bytes:
            step = min(_BLOCK, pos)
            pos -= step
            f.seek(pos)
            data = f.read(step) + data
    if lines <= 0:
        return b""
    keep = data.splitlines(keepends=True)[-lines:]
    return b"".join(keep)[-max_bytes:]


class Follower:
    """Returns what is appended to a file between calls."""

    def __init__(self, path: Path) -> None:
        self.path = path
        try:
            stat = path.stat()
            self.offset, self.inode = stat.st_size, stat.st_ino
        except FileNotFoundError:
            self.offset, self.inode = 0, 0

    def read_new(self, max_bytes: int = MAX_BYTES) -> bytes:
        """Bytes appended since the last call (from the start if the file was replaced)."""
        try:
            with self.path.open("rb") as f:
                stat = os.fstat(f.fileno())
                if stat.st_ino != self.inode or stat.st_size < self.offset:
                    self.offset, self.inode = 0, stat.st_ino
                f.seek(self.offset)
                data = f.read(max_bytes)
        except FileNotFoundError:
            return b""
        self.offset += len(data)
        return data
