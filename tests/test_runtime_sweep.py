"""An agent removes the host directories dead hosts left (a SIGKILLed agent cannot), and only
those: a live host's directory (its socket bound) and a directory made a moment ago stay."""

from __future__ import annotations

import os
import socket
import time
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.runtime.launch import listening_unix_paths, sweep_private_dirs


def host_dir(base: Path, name: str, *, listening: bool, age: float) -> tuple[Path, socket.socket]:
    path = base / f"sdrp-{name}-x"
    path.mkdir(mode=0o700)
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    sock.bind(str(path / f"{name}.sock"))
    if listening:
        sock.listen()
    else:
        sock.close()  # the file stays, nothing is bound to it: what a killed host leaves
    when = time.time() - age
    os.utime(path, (when, when))
    return path, sock


def test_only_old_directories_whose_socket_is_gone_are_removed(tmp_path: Path) -> None:
    dead, _ = host_dir(tmp_path, "Dead", listening=False, age=600)
    live, live_sock = host_dir(tmp_path, "Live", listening=True, age=600)
    young, _ = host_dir(tmp_path, "Young", listening=False, age=1)
    other = tmp_path / "not-a-host-dir"
    other.mkdir()
    os.utime(other, (0, 0))
    try:
        assert str(live / "Live.sock") in (listening_unix_paths() or set())
        assert sweep_private_dirs(time.time(), min_age=60, base=str(tmp_path)) == 1
        assert not dead.exists()
        assert [p.exists() for p in (live, young, other)] == [True, True, True]
    finally:
        live_sock.close()


def test_without_the_kernels_table_nothing_is_called_stale(tmp_path: Path) -> None:
    assert listening_unix_paths(str(tmp_path / "no-such-table")) is None


def test_a_directory_another_agent_swept_first_is_no_error(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    # Agents share the base directory and sweep it as they start (a lab starts three at once):
    # one may remove a stale directory between another's check and its own removal.
    dead, _ = host_dir(tmp_path, "Dead", listening=False, age=600)
    real_iterdir = Path.iterdir
    calls = {"n": 0}

    def iterdir_then_gone(self: Path) -> Any:
        if self == dead:
            calls["n"] += 1
            if calls["n"] == 2:  # after the sweep's check: the other agent removes it now
                for child in real_iterdir(self):
                    child.unlink()
                self.rmdir()
        return real_iterdir(self)

    monkeypatch.setattr(Path, "iterdir", iterdir_then_gone)
    assert sweep_private_dirs(time.time(), min_age=60, base=str(tmp_path)) == 1
    assert not dead.exists()
