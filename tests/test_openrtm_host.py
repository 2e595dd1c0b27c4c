"""The openrtm host over its control channel, as an agent drives it: an unmodified RTC
(tests/rtc_fixture.py) through sdrpeer's whole lifecycle and back (hello from its port profile,
activate, RTC_ERROR -> ERROR, reset, params into its configuration, exit)."""

from __future__ import annotations

from pathlib import Path

import pytest

from sdrpeer.launch.openrtm import available
from tests.hostctl import HostPool

pytestmark = [
    pytest.mark.realnet,
    pytest.mark.skipif(available() is not None, reason=f"{available()}"),
]


def test_an_rtc_follows_sdrpeers_lifecycle(hosts: HostPool, tmp_path: Path) -> None:
    trigger = tmp_path / "trip"
    host, hello = hosts.ready(
        "tests.rtc_fixture:Relay", "--param", f"trigger={trigger}", module="sdrpeer.openrtm"
    )
    assert hello["component"] == "Relay"
    assert hello["ports"] == {"in": ["pose"], "out": ["count", "echo"]}
    assert hello["params"] == {"trigger": str(trigger), "hang": "none"}  # its configuration
    assert host.command("activate")["ok"]
    host.wait_state("ACTIVE")

    trigger.write_text("trip")  # onExecute returns RTC_ERROR from now on
    error = host.wait_state("ERROR", 10.0)
    assert error["error"] == "on_execute: RtcError: Relay.onExecute returned RTC_ERROR"

    trigger.unlink()
    assert host.command("reset")["ok"]  # reset_component: onReset, INACTIVE in its context too
    host.wait_state("INACTIVE")
    assert host.command("activate")["ok"]
    host.wait_state("ACTIVE")

    # a new configuration value reaches the RTC's active set: the trigger file it names fails it
    other = tmp_path / "other"
    other.write_text("trip")
    assert host.command("set_params", params={"trigger": str(other)})["ok"]
    host.wait_state("ERROR", 10.0)

    assert host.command("exit")["ok"]
    host.wait_state("FINALIZED", 10.0)
    assert host.wait_exit(10.0) == 0
