"""A real host whose receiver refuses its stream (another data key): it says why, to its agent
(a `refused` report, once, then rate-limited) and in its log, and it exits at once when told to,
even while its component waits in `send()` on that stream (issue 30 item 5)."""

from __future__ import annotations

import socket

from tests.hostctl import HostPool, HostProc, Msg

FX = "tests.components_fixture"
SENDER_KEY = {"SDRPEER_DATA_KEYS": "11" * 32}
RECEIVER_KEY = {"SDRPEER_DATA_KEYS": "22" * 32}


def sender_to(hosts: HostPool, to: str) -> HostProc:
    """A Sequencer (it sends with `send()`), active, on a `full: block` stream to `to`."""
    pub, _ = hosts.ready("components.ledger:Sequencer", name="Pub", env=SENDER_KEY)
    conn = {
        "id": "c1",
        "out": "out",
        "to": to,
        "in": "inp",
        "policy": {"push": "fifo", "buffer": 4, "full": "block"},
    }
    assert pub.command("connect", conn=conn)["ok"] is True
    assert pub.command("activate")["ok"] is True
    return pub


def refused_pair(hosts: HostPool) -> tuple[HostProc, HostProc]:
    """A sender blocked on a stream to a Recorder that refuses its key."""
    rec, rec_hello = hosts.ready(f"{FX}:Recorder", name="Rec", env=RECEIVER_KEY)
    assert rec.command("activate")["ok"] is True
    return sender_to(hosts, f"tcp://{rec_hello['data']['tcp']}"), rec


def is_refused(m: Msg) -> bool:
    return bool(m["t"] == "refused")


def test_a_refused_sender_reports_why_once_then_rate_limited(hosts: HostPool) -> None:
    pub, _ = refused_pair(hosts)
    report = pub.wait_for(is_refused, 10.0, "a refused report")
    assert report["conn"] == "c1"
    assert report["from"] == "Pub.out"
    assert report["in"] == "inp"
    assert report["to"].startswith("tcp://127.0.0.1:")
    assert "proof" in report["error"]  # the receiver's proof does not hold under our key
    assert report["count"] == 1
    # the sender redials every <= 2 s and is refused each time: reported again only after
    # 30 s, so the next heartbeats come with no second report (bounded: 4 heartbeats, ~2 s)
    for _ in range(4):
        beat = pub.wait_t("heartbeat")
        assert not [m for m in pub.seen if is_refused(m) and m is not report]
    assert beat["ports"]["out"]["frames_sent"] == 0
    assert "refused by the receiver" in pub.log_text()
    assert pub.log_text().count("refused by the receiver") == 1


def test_a_host_blocked_in_send_on_a_refused_stream_exits_at_once(hosts: HostPool) -> None:
    """The component holds its lock in `send()` (the queue is full and nothing drains it):
    before, finalizing waited for that lock until its 5 s deadline and the host exited 1."""
    pub, _ = refused_pair(hosts)
    pub.wait_for(  # the queue (buffer 4) is full: the next send() waits for room
        lambda m: m["t"] == "heartbeat" and m["ports"]["out"]["frames_out"] >= 4,
        10.0,
        "a full queue",
    )
    reply = pub.command("exit", timeout=10.0)
    assert reply["ok"] is True, reply
    assert pub.wait_exit(10.0) == 0
    assert "finalize did not finish" not in pub.log_text()


def down_sender(hosts: HostPool) -> HostProc:
    """A sender blocked on a stream whose receiver is down (its port answers nothing), not
    refusing: `deactivate` waits for such a sender (a planned move loses nothing), unlike one on
    a refused stream."""
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    return sender_to(hosts, f"tcp://127.0.0.1:{port}")


def test_exit_is_carried_out_while_a_command_waits_on_a_blocked_sender(hosts: HostPool) -> None:
    """`deactivate` waits for the component's lock, which on_execute holds in `send()`; the
    agent's command times out and it sends `exit`. Before, `exit` queued behind `deactivate`
    and the host went on until SIGTERM; now it exits at once and answers both. (On a refused
    stream `deactivate` lets the sender go, and may finish first: the receiver is down here.)"""
    pub = down_sender(hosts)
    pub.wait_for(
        lambda m: m["t"] == "heartbeat" and m["ports"]["out"]["frames_out"] >= 4,
        10.0,
        "a full queue",
    )
    pub.send({"t": "deactivate", "id": 1000})  # hangs: nobody waits for its reply here
    reply = pub.command("exit", timeout=10.0)
    assert reply["ok"] is True, reply
    assert pub.wait_exit(10.0) == 0
    (abandoned,) = [m for m in pub.seen if m["t"] == "reply" and m["id"] == 1000]  # before exit's
    assert (abandoned["ok"], abandoned["error"]) == (False, "the host is exiting")


def test_a_component_blocked_on_a_refused_stream_can_be_deactivated(hosts: HostPool) -> None:
    """Before, `deactivate` waited for the lock on_execute held in `send()` on the refused
    stream, until the agent's command timed out (and a stop took that long)."""
    pub, _ = refused_pair(hosts)
    pub.wait_for(is_refused, 10.0, "a refused report")
    pub.wait_for(
        lambda m: m["t"] == "heartbeat" and m["ports"]["out"]["frames_out"] >= 4,
        10.0,
        "a full queue",
    )
    assert pub.command("deactivate", timeout=10.0)["ok"] is True
    pub.wait_state("INACTIVE")
    dropped = pub.wait_t("heartbeat")["ports"]["out"]["dropped"]
    assert dropped == 1  # the value the blocked send() held: refused, counted
    assert pub.command("exit")["ok"] is True
    assert pub.wait_exit() == 0
