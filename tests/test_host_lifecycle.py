"""A real host driven through its control channel: hello, lifecycle, params, errors, faults."""

from __future__ import annotations

import contextlib
import time
from pathlib import Path

import msgpack

from tests.hostctl import HostPool

FX = "tests.components_fixture"


def test_hello_then_inactive(hosts: HostPool, tmp_path: Path) -> None:
    host = hosts.spawn(f"{FX}:Tunable", "--param", "gain=2.5", name="Tune1")
    first = host.recv(10.0)
    assert first is not None
    assert first["t"] == "hello"
    assert first["protocol"] == 1
    assert first["pid"] == host.proc.pid
    assert first["component"] == "Tunable"
    assert first["ports"] == {"in": [], "out": ["out"]}
    assert first["params"] == {"gain": 2.5, "mode": "fast", "enabled": True, "count": 3}
    assert first["data"]["tcp"].startswith("127.0.0.1:")
    assert first["data"]["unix"] == str(tmp_path / "Tune1.sock")
    state = host.wait_t("state")
    assert (state["state"], state["error"]) == ("INACTIVE", None)
    assert abs(state["ts"] - time.time()) < 5


def test_lifecycle_commands(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter")
    assert host.command("activate")["ok"] is True
    assert host.wait_state("ACTIVE")["error"] is None
    again = host.command("activate")
    assert again["ok"] is False
    assert "already active" in again["error"]
    assert host.command("reset")["ok"] is False
    assert host.command("deactivate")["ok"] is True
    host.wait_state("INACTIVE")
    reply = host.command("exit", timeout=5.0)
    assert (reply["ok"], reply["error"]) == (True, None)
    states = [m["state"] for m in host.seen if m["t"] == "state"]
    assert states == ["INACTIVE", "ACTIVE", "INACTIVE", "FINALIZED"]
    assert host.wait_exit() == 0


def test_exit_while_active_deactivates_first(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter")
    host.command("activate")
    assert host.command("exit", timeout=10.0)["ok"] is True
    assert [m["state"] for m in host.seen if m["t"] == "state"][-2:] == ["INACTIVE", "FINALIZED"]
    assert host.wait_exit() == 0


def test_heartbeat_carries_counters(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter", "--param", "rate=200")
    host.command("activate")
    first = host.wait_t("heartbeat", 2.0)
    second = host.wait_t("heartbeat", 2.0)
    assert 0.45 <= second["ts"] - first["ts"] < 5.0  # every 0.5 s; late when the host is busy
    assert set(second["ports"]["out"]) >= {
        "frames_in",
        "bytes_in",
        "frames_out",
        "bytes_out",
        "dropped",
        "lost",
        "refused",
    }
    assert second["ports"]["out"]["frames_out"] > first["ports"]["out"]["frames_out"] > 0


def test_set_params_visible(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Tunable")
    ok = host.command("set_params", params={"gain": 7.5, "mode": "slow"})
    assert ok["ok"] is True, ok
    bad = host.command("set_params", params={"gain": 11})
    assert bad["ok"] is False
    assert "gain" in bad["error"]
    assert "above max" in bad["error"]
    unknown = host.command("set_params", params={"nope": 1})
    assert unknown["ok"] is False
    assert "nope" in unknown["error"]
    not_a_map = host.command("set_params", params=[1])
    assert not_a_map["ok"] is False
    assert not_a_map["error"] == "set_params: 'params' must be a map, got [1]"
    host.command("exit")
    host.wait_exit()
    assert "params changed: [('gain', 7.5), ('mode', 'slow')]" in host.log_text()


def test_bad_param_on_the_command_line_exits_2(hosts: HostPool) -> None:
    host = hosts.spawn(f"{FX}:Tunable", "--param", "mode=medium")
    assert host.wait_exit() == 2
    assert "param 'mode'" in host.log_text()


def test_exception_in_on_execute_reports_error_at_once(hosts: HostPool, tmp_path: Path) -> None:
    """The ERROR report leaves in the loop iteration that raised (the SDK's own test pins that
    without a clock); here only that it arrives, not after the next heartbeat or later."""
    stamp = tmp_path / "raised_at"
    host, _ = hosts.ready(f"{FX}:Crasher", "--param", "after=20", "--param", f"stamp={stamp}")
    host.command("activate")
    error = host.wait_state("ERROR", 5.0)
    raised_at = float(stamp.read_text())
    # Arrival (our clock, stamped on receipt) minus the moment the component raised.
    assert 0 <= error["_rx"] - raised_at < 2.0, error["_rx"] - raised_at
    assert "crash after 20 periods" in error["error"]
    assert host.command("activate")["ok"] is False
    assert host.command("reset")["ok"] is True
    host.wait_state("INACTIVE")
    assert host.command("exit")["ok"] is True
    assert host.wait_exit() == 0


def test_fault_is_forwarded(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Faulty")
    host.command("activate")
    fault = host.wait_t("fault")
    assert (fault["kind"], fault["detail"]) == ("hardware_failure", "motor 2 overheated")
    assert abs(fault["ts"] - time.time()) < 5
    error = host.wait_state("ERROR")  # a hardware failure moves to ERROR, saying which fault
    assert (error["error"], error["fault"]) == (
        "hardware_failure: motor 2 overheated",
        "hardware_failure",
    )


def test_unknown_and_malformed_commands(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter")
    reply = host.command("dance")
    assert (reply["ok"], reply["error"]) == (False, "unknown command 'dance'")
    assert (
        "no OutPort 'nope'"
        in host.command(
            "connect", conn={"id": "c", "out": "nope", "to": "tcp://127.0.0.1:1", "in": "x"}
        )["error"]
    )
    assert (
        "'to'"
        in host.command(
            "connect", conn={"id": "c", "out": "out", "to": "carrier-pigeon", "in": "x"}
        )["error"]
    )
    assert "'conn' must be a map" in host.command("connect", conn="c")["error"]
    bad_to = host.command("connect", conn={"id": "c", "out": "out", "to": 5, "in": "x"})
    assert bad_to["error"] == "connect: 'conn.to' must be a string, got 5"
    assert "no connection 'zz'" in host.command("disconnect", conn_id="zz")["error"]
    host.send({"t": "activate"})  # no id: logged and skipped, the channel stays up
    assert host.command("activate")["ok"] is True


def test_protocol_error_closes_the_channel_and_the_host_exits(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter")
    host.sock.sendall(msgpack.packb([1, 2, 3]))
    assert host.wait_exit(5.0) == 0
    assert "protocol error: expected a map, got list" in host.log_text()


def test_oversized_message_closes_the_channel(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter")
    blob = b"x" * ((1 << 20) + 10)
    with contextlib.suppress(BrokenPipeError, ConnectionResetError):  # it may close first
        host.send({"t": "set_params", "id": 1, "params": {"rate": blob}})
    assert host.wait_exit(5.0) == 0
    assert "protocol error" in host.log_text()


def test_commands_queued_behind_exit_are_still_answered(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter")
    host.send({"t": "exit", "id": 100})
    host.send({"t": "activate", "id": 101})
    late = host.wait_for(lambda m: m["t"] == "reply" and m["id"] == 101, what="reply 101")
    assert (late["ok"], late["error"]) == (False, "the host is exiting")
    assert [m["id"] for m in host.seen if m["t"] == "reply"] == [100, 101]
    assert host.wait_exit() == 0
