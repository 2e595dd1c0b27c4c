"""Real hosts connected by data streams: connect, frames arrive, repoint live, disconnect."""

from __future__ import annotations

import pytest

from tests.hostctl import HostPool, HostProc

FX = "tests.components_fixture"


def frames_in(host: HostProc, timeout: float = 2.0) -> dict[str, int]:
    """The receiver's `inp` counters from its next heartbeat."""
    counters: dict[str, int] = host.wait_t("heartbeat", timeout)["ports"]["inp"]
    return counters


def wait_frames(host: HostProc, more_than: int, timeout: float = 5.0) -> dict[str, int]:
    """Heartbeats until the receiver has counted more than `more_than` frames in."""
    seen: dict[str, int] = {}
    for _ in range(int(timeout / 0.5) + 1):
        seen = frames_in(host)
        if seen["frames_in"] > more_than:
            return seen
    raise AssertionError(f"receiver stuck at {seen} (wanted > {more_than}): {host.log_text()}")


def conn(to: str, conn_id: str = "c1", **policy: object) -> dict[str, object]:
    """A connection map from the counter's `out` to a recorder's `inp`."""
    return {"id": conn_id, "out": "out", "to": to, "in": "inp", "policy": policy}


@pytest.mark.parametrize("kind", ["tcp", "unix"])
def test_publisher_to_receiver(hosts: HostPool, kind: str) -> None:
    pub, _ = hosts.ready(f"{FX}:Counter", "--param", "rate=200", name="Pub")
    rec, rec_hello = hosts.ready(f"{FX}:Recorder", name="Rec")
    assert rec_hello["ports"] == {"in": ["inp"], "out": []}
    address = rec_hello["data"][kind]
    to = f"tcp://{address}" if kind == "tcp" else f"unix://{address}"
    assert rec.command("activate")["ok"] is True
    reply = pub.command("connect", conn=conn(to, push="fifo", buffer=64))
    assert reply["ok"] is True, reply
    assert pub.command("connect", conn=conn(to))["error"] == "connection 'c1' already exists"
    assert pub.command("activate")["ok"] is True
    counters = wait_frames(rec, 50)
    assert counters["lost"] == 0
    assert counters["refused"] == 0
    # ints have no length: bytes_in is what the data server received for the port (each frame
    # [seq, n] is at least 3 bytes of msgpack)
    assert counters["bytes_in"] >= 3 * counters["frames_in"]
    beat = rec.wait_t("heartbeat")
    assert beat["data"]["accepted"] == 1  # the data server's counters travel too
    # the publisher's next heartbeat may have been queued before those frames went out: read
    # on (a bounded number) until one counts them
    out: dict[str, int] = {}
    for _ in range(20):
        out = pub.wait_t("heartbeat")["ports"]["out"]
        if out["frames_out"] > 50:
            break
    assert out["frames_out"] > 50
    assert out["bytes_out"] > 0
    assert 0 < out["frames_sent"] <= out["frames_out"]  # written vs handed to the socket
    assert pub.command("disconnect", conn_id="c1")["ok"] is True
    assert pub.command("exit")["ok"] is True
    assert rec.command("exit")["ok"] is True
    assert pub.wait_exit() == 0
    assert rec.wait_exit() == 0
    assert "recorded" in rec.log_text()


def test_repoint_a_live_connection(hosts: HostPool) -> None:
    pub, _ = hosts.ready(f"{FX}:Counter", "--param", "rate=200", name="Pub")
    first, first_hello = hosts.ready(f"{FX}:Recorder", name="RecA")
    second, second_hello = hosts.ready(f"{FX}:Recorder", name="RecB")
    for rec in (first, second):
        rec.command("activate")
    to_first = f"unix://{first_hello['data']['unix']}"
    to_second = f"tcp://{second_hello['data']['tcp']}"
    assert pub.command("connect", conn=conn(to_first))["ok"] is True
    pub.command("activate")
    wait_frames(first, 20)
    assert pub.command("repoint", conn_id="c1", to=to_second)["ok"] is True
    moved = wait_frames(second, 20)
    # Sequence numbers continue across the repoint: the new receiver sees no gap after its first.
    assert moved["lost"] == 0
    frozen = frames_in(first)["frames_in"]
    assert frames_in(first)["frames_in"] == frozen  # nothing more reaches the old one
    assert wait_frames(second, moved["frames_in"])["frames_in"] > moved["frames_in"]
    bad = pub.command("repoint", conn_id="c1", to="ftp://x")
    assert bad["ok"] is False
    assert "'to'" in bad["error"]
    assert pub.command("repoint", conn_id="zz", to=to_first)["ok"] is False


def test_receiver_refuses_unknown_port_and_connection_keeps_retrying(hosts: HostPool) -> None:
    pub, _ = hosts.ready(f"{FX}:Counter", "--param", "rate=100", name="Pub")
    rec, rec_hello = hosts.ready(f"{FX}:Recorder", name="Rec")
    bad = conn(f"tcp://{rec_hello['data']['tcp']}")
    bad["in"] = "nope"
    assert pub.command("connect", conn=bad)["ok"] is True  # the stream itself is asynchronous
    pub.command("activate")
    assert frames_in(rec)["frames_in"] == 0
    assert pub.command("exit", timeout=10.0)["ok"] is True
    assert pub.wait_exit() == 0


def test_hosts_with_data_keys_authenticate_and_take_new_keys(hosts: HostPool) -> None:
    """Two hosts with the old key talk; the receiver alone moves to a new key and the sender
    cannot get in any more; once the sender has the new key too, frames flow again."""
    old, new = "11" * 32, "22" * 32
    keys = {"SDRPEER_DATA_KEYS": old}
    pub, _ = hosts.ready(f"{FX}:Counter", "--param", "rate=200", name="Pub", env=keys)
    rec, rec_hello = hosts.ready(f"{FX}:Recorder", name="Rec", env=keys)
    to = f"tcp://{rec_hello['data']['tcp']}"
    assert rec.command("activate")["ok"] is True
    assert pub.command("connect", conn=conn(to, push="fifo", buffer=64))["ok"] is True
    assert pub.command("activate")["ok"] is True
    wait_frames(rec, 20)
    assert rec.command("data_keys", keys=[new])["ok"] is True
    assert rec.command("data_keys", keys=["zz"])["error"] == "'keys': expected hex strings"
    assert pub.command("disconnect", conn_id="c1")["ok"] is True
    assert pub.command("connect", conn=conn(to, "c2", push="fifo", buffer=64))["ok"] is True
    before = frames_in(rec)["frames_in"]
    for _ in range(3):  # three heartbeats (~1.5 s): the sender redials, and is refused each time
        assert frames_in(rec)["frames_in"] == before
    refused = rec.wait_t("heartbeat")["data"]["refused_auth"]
    assert refused >= 1  # the receiver says why nothing arrives
    assert pub.command("data_keys", keys=[new, old])["ok"] is True
    wait_frames(rec, before + 20)  # the sender redials with the new key
