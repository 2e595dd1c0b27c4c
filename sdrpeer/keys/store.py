"""Where an agent keeps its keyring: the key file it was given, and its own copy in its data
directory that key commands and reloads write.

How it works: `--key-file` is the operator's file (maybe read-only, maybe shared by a lab's
robots); the agent never writes it. Every change of the ring in use (a `sdrpeer key` command, a
SIGHUP reload) is saved to `DATA_DIR/keyring` (same format, mode 0600, written atomically), so a
restarted agent keeps a rotation it took part in. At start and on SIGHUP the agent takes the
*newer* of the two files (modification time; the data-dir copy on a tie): a rotation done with
`sdrpeer key` survives restarts, and an operator who edits the key file by hand (a robot that
missed a rotation) makes it win again, with no file to delete. The rule trusts the robot's
clock between the two writes: on a robot whose clock was set back (no RTC, no NTP) a hand edit
may look older than the saved ring; deleting DATA_DIR/keyring then makes the key file count.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Final

from sdrpeer.errors import ConfigError
from sdrpeer.keys.keyring import Keyring

__all__ = ["KEYRING_FILE", "load_ring", "newer_source", "save_ring"]

KEYRING_FILE: Final = "keyring"
_COMMENT: Final = (
    "sdrpeer keyring, written by the agent (sdrpeer key ...): the first key seals, all open.\n"
    "Edit the agent's --key-file instead: the newer of the two files is used."
)


def _mtime(path: Path) -> int | None:
    try:
        return path.stat().st_mtime_ns
    except OSError:
        return None


def newer_source(key_file: Path, data_dir: Path) -> Path:
    """The file the ring is read from: DATA_DIR/keyring when it exists and is not older than
    `key_file`, else `key_file`."""
    saved = data_dir / KEYRING_FILE
    saved_at = _mtime(saved)
    if saved_at is None:
        return key_file
    given_at = _mtime(key_file)
    return saved if given_at is None or saved_at >= given_at else key_file


def load_ring(key_file: Path, data_dir: Path) -> tuple[Keyring, Path]:
    """The ring to use and the file it came from (ConfigError naming the file and line)."""
    source = newer_source(key_file, data_dir)
    return Keyring.from_file(source), source


def save_ring(data_dir: Path, ring: Keyring) -> Path:
    """Write `ring` to DATA_DIR/keyring (0600, atomically); its path. ConfigError when the
    directory cannot be written (the ring in memory is in use all the same)."""
    path = data_dir / KEYRING_FILE
    tmp = path.with_name(KEYRING_FILE + ".tmp")
    try:
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w", encoding="utf-8") as out:
            out.write(ring.to_text(_COMMENT))
            out.flush()
            os.fsync(out.fileno())
        os.chmod(tmp, 0o600)
        os.replace(tmp, path)
    except OSError as exc:
        raise ConfigError(f"{path}: cannot save the keyring: {exc}") from exc
    return path
