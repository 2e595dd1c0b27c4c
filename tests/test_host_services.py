"""Real hosts bound by service ports: a caller's host calls a provider's host over the data
plane (with data keys, so authenticated and encrypted), as the agent's commands connect,
re-point and disconnect the binding."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from sdrpeer.keys.derive import data_key
from tests.components_fixture import ECHO, OTHER_ECHO
from tests.hostctl import HostPool, HostProc

FX = "tests.components_fixture"
KEYS = {"SDRPEER_DATA_KEYS": data_key(b"\x05" * 32).hex()}


def beat_until(
    host: HostProc, ok: Callable[[dict[str, Any]], bool], what: str, beats: int = 20
) -> dict[str, Any]:
    """Heartbeats (at most `beats`, one every 0.5 s) until one's `ports` pass `ok`."""
    ports: dict[str, Any] = {}
    for _ in range(beats):
        ports = host.wait_t("heartbeat", 2.0)["ports"]
        if ok(ports):
            return ports
    raise AssertionError(f"no heartbeat with {what}; last ports {ports}: {host.log_text()[-2000:]}")


def binding(to: str, out: str = "svc", conn_id: str = "b1") -> dict[str, Any]:
    """A service binding from the caller's `out` to the provider's `svc`."""
    return {"id": conn_id, "out": out, "to": to, "in": "svc"}


def start_provider(hosts: HostPool, name: str) -> tuple[HostProc, str]:
    host, hello = hosts.ready(f"{FX}:EchoService", name=name, env=KEYS)
    assert hello["services"] == {
        "svc": {"role": "provides", "interface": ECHO.id, "methods": ["echo", "boom", "slow"]}
    }
    assert host.command("activate")["ok"] is True
    return host, f"tcp://{hello['data']['tcp']}"


def test_calls_between_hosts_errors_and_activity(hosts: HostPool) -> None:
    echo, to = start_provider(hosts, "Echo")
    caller, hello = hosts.ready(f"{FX}:EchoCaller", name="Caller", env=KEYS)
    assert hello["services"]["other"]["interface"] == OTHER_ECHO.id
    assert hello["ports"] == {"in": [], "out": ["out"]}
    assert caller.command("connect", conn=binding(to))["ok"] is True
    reply = caller.command("connect", conn=binding(to, conn_id="b2"))
    assert reply["error"] == "service port 'svc' is bound already"
    assert caller.command("activate")["ok"] is True
    ports = beat_until(caller, lambda p: p["out"]["frames_out"] >= 10, "10 echoes")
    assert ports["svc"]["failed"] == 0
    served = beat_until(echo, lambda p: p["svc"]["calls"] >= 10, "10 calls served")
    assert served["svc"]["failed"] == 0

    # a provider that is not ACTIVE answers ServiceUnavailable; it serves again once activated
    assert echo.command("deactivate")["ok"] is True
    ports = beat_until(caller, lambda p: p["svc"]["unavailable"] >= 3, "calls unavailable")
    assert echo.command("activate")["ok"] is True
    before = ports["out"]["frames_out"]
    beat_until(caller, lambda p: p["out"]["frames_out"] > before + 5, "echoes again")

    # the provider's handler raises: ServiceError at the caller, the provider stays ACTIVE
    assert caller.command("set_params", params={"method": "boom"})["ok"] is True
    failed = ports["svc"]["failed"]
    ports = beat_until(caller, lambda p: p["svc"]["failed"] >= failed + 5, "errors")
    assert ports["svc"]["timeouts"] == 0
    # no reply within the caller's 0.3 s: ServiceTimeout
    assert caller.command("set_params", params={"method": "slow"})["ok"] is True
    beat_until(caller, lambda p: p["svc"]["timeouts"] >= 2, "timeouts")
    assert not [m for m in echo.seen if m["t"] == "state" and m["state"] == "ERROR"]

    # a consumer of another interface is refused by the provider's host
    assert caller.command("connect", conn=binding(to, "other", "b3"))["ok"] is True
    beat = echo.wait_for(
        lambda m: m["t"] == "heartbeat" and m["data"].get("refused_interface", 0) > 0,
        10.0,
        "refused_interface",
    )
    assert beat["ports"]["svc"]["calls"] > 10
    assert "interface mismatch: Caller.other requires test/Echo#" in echo.log_text()
    # ...and the caller's host tells its agent why (issue 30 item 5)
    refused = caller.wait_for(
        lambda m: m["t"] == "refused" and m["conn"] == "b3", 10.0, "a refused report"
    )
    assert (refused["from"], refused["in"], refused["to"]) == ("Caller.other", "svc", to)
    assert "interface mismatch: Caller.other requires" in refused["error"]
    assert caller.command("disconnect", conn_id="b1")["ok"] is True
    assert caller.command("disconnect", conn_id="b1")["error"] == "no connection 'b1'"
    assert caller.command("exit")["ok"] is True
    assert echo.command("exit")["ok"] is True
    assert caller.wait_exit() == 0
    assert echo.wait_exit() == 0


def test_repoint_moves_the_calls_to_another_provider(hosts: HostPool) -> None:
    old, old_to = start_provider(hosts, "Old")
    new, new_to = start_provider(hosts, "New")
    caller, _ = hosts.ready(f"{FX}:EchoCaller", name="Caller", env=KEYS)
    assert caller.command("connect", conn=binding(old_to))["ok"] is True
    assert caller.command("activate")["ok"] is True
    beat_until(old, lambda p: p["svc"]["calls"] >= 5, "calls at the old provider")
    assert caller.command("repoint", conn_id="b1", to=new_to)["ok"] is True
    assert caller.command("repoint", conn_id="b1", to="nowhere")["error"].startswith("'to': ")
    beat_until(new, lambda p: p["svc"]["calls"] >= 5, "calls at the new provider")
    stays = old.wait_t("heartbeat", 2.0)["ports"]["svc"]["calls"]
    ports = beat_until(caller, lambda p: p["out"]["frames_out"] >= 10, "10 echoes")
    assert ports["svc"]["failed"] <= 1  # at most the call in flight during the repoint
    assert old.wait_t("heartbeat", 2.0)["ports"]["svc"]["calls"] == stays
