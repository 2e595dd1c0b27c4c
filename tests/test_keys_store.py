"""Keyring changes (add, primary, retire), the saved ring and the newer-file rule, and a key
sealed for one robot: pure, no agent."""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.agent.keyadmin import apply_change, parse_change, ring_json
from sdrpeer.errors import ConfigError
from sdrpeer.keys.keyring import Keyring, format_key, key_id, parse_key_id
from sdrpeer.keys.store import KEYRING_FILE, load_ring, newer_source, save_ring
from sdrpeer.keys.transport import open_key, seal_key

A, B, C = (bytes([n]) * 32 for n in (1, 2, 3))


def ids(ring: Keyring) -> list[bytes]:
    return list(ring.keys)


@pytest.mark.parametrize(
    ("start", "op", "arg", "after"),
    [
        ([A], "add", B, [A, B]),
        ([A, B], "add", B, [A, B]),  # already in: nothing changes
        ([A, B], "primary", B, [B, A]),
        ([B, A], "primary", B, [B, A]),
        ([B, A], "retire", A, [B]),
        ([B], "retire", A, [B]),  # already gone: nothing changes
        ([A, B, C], "primary", C, [C, A, B]),
    ],
)
def test_each_change_makes_the_ring_the_rotation_needs(
    start: list[bytes], op: str, arg: bytes, after: list[bytes]
) -> None:
    key = arg if op == "add" else None
    kid = None if op == "add" else key_id(arg)
    assert ids(apply_change(Keyring(start), op, key, kid)) == after


def test_changes_that_would_lock_robots_out_are_refused() -> None:
    with pytest.raises(ConfigError, match="primary"):
        Keyring([A, B]).without(key_id(A))  # the sealing key
    with pytest.raises(ConfigError, match="install it first"):
        Keyring([A]).with_primary(key_id(B))
    with pytest.raises(ConfigError, match="unknown key operation"):
        apply_change(Keyring([A]), "drop", None, key_id(A))
    with pytest.raises(ValueError, match="8 hex digits"):
        parse_key_id("xyz")


def test_the_saved_ring_is_private_and_the_newer_file_wins(tmp_path: Path) -> None:
    key_file = tmp_path / "cluster.key"
    key_file.write_text(format_key(A) + "\n")
    data = tmp_path / "data"
    data.mkdir()
    assert newer_source(key_file, data) == key_file  # nothing saved yet
    saved = save_ring(data, Keyring([B, A]))
    assert saved == data / KEYRING_FILE
    assert stat.S_IMODE(saved.stat().st_mode) == 0o600
    ring, source = load_ring(key_file, data)
    assert (ids(ring), source) == ([B, A], saved)  # a restart keeps the rotation
    # an operator edits the key file by hand later: it wins, no file to delete
    key_file.write_text(format_key(C) + "\n")
    later = saved.stat().st_mtime_ns + 1_000_000_000
    os.utime(key_file, ns=(later, later))
    ring, source = load_ring(key_file, data)
    assert (ids(ring), source) == ([C], key_file)
    assert "#" in saved.read_text()  # says who wrote it
    assert Keyring.from_file(saved).keys == (B, A)


def test_a_sealed_key_opens_only_for_its_robot_and_only_with_the_ring() -> None:
    sender = Keyring([A])
    doc = seal_key(sender, C, "robot-2")
    assert C.hex() not in str(doc)
    assert open_key(Keyring([B, A]), doc, "robot-2") == C  # any key of the ring with that id
    with pytest.raises(ConfigError, match="another robot"):
        open_key(Keyring([A]), doc, "robot-3")
    with pytest.raises(ConfigError, match="no key with id"):
        open_key(Keyring([B]), doc, "robot-2")
    flipped = dict(doc, sealed=("00" if doc["sealed"][:2] != "00" else "11") + doc["sealed"][2:])
    with pytest.raises(ConfigError, match="does not open"):
        open_key(Keyring([A]), flipped, "robot-2")
    for bad in (None, {"by": "zz"}, {"by": key_id(A).hex(), "nonce": "00", "sealed": ""}):
        with pytest.raises(ConfigError, match='field "key'):
            open_key(Keyring([A]), bad, "robot-2")


def test_a_robot_to_robot_change_names_the_bad_field() -> None:
    ring = Keyring([A])
    with pytest.raises(ConfigError, match='field "op"'):
        parse_change({"op": "install"}, ring, "robot-1")
    with pytest.raises(ConfigError, match='field "key_id"'):
        parse_change({"op": "retire", "key_id": 7}, ring, "robot-1")
    assert parse_change({"op": "primary", "key_id": key_id(A).hex()}, ring, "r") == (
        "primary",
        None,
        key_id(A),
    )
    assert ring_json("r", Keyring([B, A])) == {
        "name": "r",
        "primary": key_id(B).hex(),
        "keys": [key_id(B).hex(), key_id(A).hex()],
    }


def test_primary_and_retire_wait_for_every_alive_robot_but_not_for_the_dead() -> None:
    from sdrpeer.agent.keyadmin import KeyAdmin, KeyChangeRefused  # noqa: PLC0415

    new, old = key_id(B).hex(), key_id(A).hex()
    both = {"primary": old, "keys": [old, new]}
    listing: dict[str, Any] = {
        "robots": {"r1": both, "r2": {"error": "timed out"}},
        "not_alive": ["r3"],
    }
    with pytest.raises(KeyChangeRefused, match="r2 did not answer"):
        KeyAdmin._check(listing, "primary", key_id(B))
    listing["robots"]["r2"] = {"primary": old, "keys": [old]}
    with pytest.raises(KeyChangeRefused, match="r2 does not hold key"):
        KeyAdmin._check(listing, "primary", key_id(B))
    listing["robots"]["r2"] = both
    KeyAdmin._check(listing, "primary", key_id(B))  # r3 is dead: it cannot be asked
    with pytest.raises(KeyChangeRefused, match="r1 seals with key"):
        KeyAdmin._check(listing, "retire", key_id(A))
