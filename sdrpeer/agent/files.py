"""The agent's files in its data directory: the API token, agent.json and the floors.

How it works: the token is read from `--token-file` (which must exist) or `DATA_DIR/token`,
generated (mode 0600) when absent. `agent.json` (name, gossip and API addresses, pid) is written
atomically once the agent is fully started (its API answers a little before: /healthz `ready`),
so a lab or a person can find the agent and use every route. `seq_start`
picks the first gossip seq: wall-clock microseconds, but never below `DATA_DIR/seq.floor`, which
it then moves `SEQ_RESERVE` past what it returns — so seqs keep rising across restarts even when
the clock went back (receivers would refuse lower ones as replays). `record.floor` does the
same for the versions of this robot's gossip record (`record_versions`): a new life starts past
every version an old one may have spread, so no robot keeps an old life's bytes under a version
the new life reuses. `clock.offset` keeps the gossip codec's cluster-time offset
(sdrpeer.gossip.wire) across restarts.
"""

from __future__ import annotations

import json
import os
import secrets
from pathlib import Path

from sdrpeer.errors import ConfigError

SEQ_RESERVE = 10**12
"""Seqs one run may use (a million datagrams a second for eleven days)."""


def seq_start(data_dir: Path, now_us: int) -> int:
    """The first gossip seq of this run (see the module docstring)."""
    path = data_dir / "seq.floor"
    try:
        floor = int(path.read_text().strip())
    except (OSError, ValueError):
        floor = 0
    start = max(now_us, floor)
    tmp = path.with_name("seq.floor.tmp")
    tmp.write_text(f"{start + SEQ_RESERVE}\n")
    os.replace(tmp, path)
    return start


RECORD_RESERVE = 1_000_000
"""Record versions one run takes before it moves `record.floor` again."""


def _read_floor(path: Path) -> int:
    try:
        return max(0, int(path.read_text().strip()))
    except (OSError, ValueError):
        return 0


def _write_floor(path: Path, value: int) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(f"{value}\n")
    os.replace(tmp, path)


def record_versions(data_dir: Path) -> tuple[int, int]:
    """(first record version of this run, the limit now reserved): the floor kept in
    DATA_DIR/record.floor, which moves `RECORD_RESERVE` on."""
    path = data_dir / "record.floor"
    first = max(1, _read_floor(path))
    limit = first + RECORD_RESERVE
    _write_floor(path, limit)
    return first, limit


def reserve_record_versions(data_dir: Path, version: int) -> int:
    """Move the floor `RECORD_RESERVE` past `version` (a run that used up its reserve);
    returns the new limit."""
    limit = version + RECORD_RESERVE
    _write_floor(data_dir / "record.floor", limit)
    return limit


def load_token(data_dir: Path, token_file: Path | None) -> str:
    """The API token: from `token_file`, else DATA_DIR/token (generated when absent)."""
    path = token_file or data_dir / "token"
    if path.is_file():
        token = path.read_text().strip()
        if not token:
            raise ConfigError(f"{path}: the token file is empty")
        return token
    if token_file is not None:
        raise ConfigError(f"{path}: token file not found")
    token = secrets.token_hex(32)  # hex: never starts with "-" (as `--token -x...` it was a flag)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(token + "\n")
    return token


def write_agent_json(data_dir: Path, name: str, addr: tuple[str, int], api: str | None) -> None:
    """DATA_DIR/agent.json, atomically."""
    info = {"name": name, "gossip": f"{addr[0]}:{addr[1]}", "api": api, "pid": os.getpid()}
    path = data_dir / "agent.json"
    tmp = path.with_suffix(".tmp")
    tmp.write_text(json.dumps(info))
    tmp.replace(path)


def load_clock_offset(data_dir: Path) -> int:
    """The cluster-time offset (ms) this robot last ran with (0 when none is recorded)."""
    try:
        return max(0, int((data_dir / "clock.offset").read_text().strip()))
    except (OSError, ValueError):
        return 0


def keep_clock_offset(data_dir: Path, offset_ms: int, saved_ms: int) -> int:
    """Record the cluster-time offset for the next start if it moved since `saved_ms`; returns
    what is recorded now."""
    if offset_ms != saved_ms:
        save_clock_offset(data_dir, offset_ms)
    return offset_ms


def save_clock_offset(data_dir: Path, offset_ms: int) -> None:
    """Record the cluster-time offset (atomically), for the next start."""
    path = data_dir / "clock.offset"
    tmp = path.with_name("clock.offset.tmp")
    tmp.write_text(f"{offset_ms}\n")
    os.replace(tmp, path)
