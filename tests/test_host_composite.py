"""A real composite host (`python -m sdrpeer.host --composite ...`): one process, one hello
with the members' ports and params as `Member.name`, data from an ordinary host into a member's
InPort and from a member's OutPort to an ordinary host, per-port heartbeat counters, and a
member's failure reported as the composite's ERROR naming the member."""

from __future__ import annotations

import re

from tests.hostctl import HostPool, HostProc, Msg

FX = "tests.components_fixture"
CF = "tests.composite_fixture"
PIPE = f"periodic:100;Src={CF}:Source;Dbl={CF}:Doubler"


def port_counters(host: HostProc, port: str, key: str, more_than: int) -> dict[str, int]:
    """Heartbeats (bounded) until `port`'s `key` counter passes `more_than`."""
    seen: dict[str, int] = {}
    for _ in range(20):
        seen = host.wait_t("heartbeat", 2.0)["ports"][port]
        if seen[key] > more_than:
            return seen
    raise AssertionError(f"{port} stuck at {seen}: {host.log_text()}")


def to(hello: Msg) -> str:
    return f"unix://{hello['data']['unix']}"


def test_a_composite_host_exchanges_data_with_ordinary_hosts(hosts: HostPool) -> None:
    pipe, hello = hosts.ready("--composite", PIPE, "--param", "Dbl.gain=3", name="Pipe")
    assert hello["component"] == "Pipe"
    assert hello["ports"] == {"in": ["Dbl.inp"], "out": ["Src.out", "Dbl.out"]}
    assert hello["params"] == {"Src.step": 1, "Dbl.fail_at": 0, "Dbl.gain": 3}
    pub, _ = hosts.ready(f"{FX}:Counter", "--param", "rate=200", name="Pub")
    rec, rec_hello = hosts.ready(f"{FX}:Recorder", name="Rec")
    # an ordinary host feeds a member's InPort; a member's OutPort feeds an ordinary host
    into = {"id": "in", "out": "out", "to": to(hello), "in": "Dbl.inp", "policy": {}}
    assert pub.command("connect", conn=into)["ok"] is True
    out = {"id": "out", "out": "Dbl.out", "to": to(rec_hello), "in": "inp", "policy": {}}
    assert pipe.command("connect", conn=out)["ok"] is True
    bad = {"id": "bad", "out": "out", "to": to(rec_hello), "in": "inp", "policy": {}}
    refused = pipe.command("connect", conn=bad)
    assert refused["ok"] is False
    assert "Dbl.out" in refused["error"]  # its OutPorts are named Member.port
    assert pipe.command("set_params", params={"Dbl.gain": 1000})["ok"] is True
    bad_param = pipe.command("set_params", params={"gain": 5})
    assert bad_param["ok"] is False
    assert "unknown param" in bad_param["error"]
    for host in (rec, pipe, pub):
        assert host.command("activate")["ok"] is True
    got = port_counters(rec, "inp", "frames_in", 30)
    assert got["lost"] == 0
    beat = port_counters(pipe, "Dbl.inp", "frames_in", 30)
    assert beat["refused"] == 0
    assert port_counters(pipe, "Dbl.out", "frames_out", 30)["frames_out"] > 30
    for host in (pub, pipe, rec):
        assert host.command("exit")["ok"] is True
        assert host.wait_exit() == 0
    last = re.search(r"recorded (\d+) values, last \[(\d+)\]", rec.log_text())
    assert last is not None, rec.log_text()
    assert int(last.group(2)) > 0
    assert int(last.group(2)) % 1000 == 0  # every value went through Dbl, with the new gain


def test_a_failing_member_puts_the_composite_host_in_error_naming_it(hosts: HostPool) -> None:
    pipe, hello = hosts.ready("--composite", PIPE, "--param", "Dbl.fail_at=4", name="Pipe")
    # inside the composite: Src.out -> Dbl.inp, through the host's own data server
    loop = {"id": "loop", "out": "Src.out", "to": to(hello), "in": "Dbl.inp", "policy": {}}
    assert pipe.command("connect", conn=loop)["ok"] is True
    assert pipe.command("activate")["ok"] is True
    error = pipe.wait_state("ERROR", 10.0)
    assert "member Dbl: on_execute: ValueError: cannot double 4" in error["error"]
    assert pipe.command("exit")["ok"] is True
    assert pipe.wait_exit() == 0


def test_a_composite_host_that_cannot_load_a_member_says_which(hosts: HostPool) -> None:
    bad = f"stepped;Src={CF}:Source;Ghost={CF}:NoSuchClass"
    host = hosts.spawn("--composite", bad, name="Bad")
    assert host.wait_exit(10.0) == 2
    assert "member Ghost" in host.log_text()
    assert "NoSuchClass" in host.log_text()


def test_a_stepped_composite_host_runs_its_members_on_the_step_command(hosts: HostPool) -> None:
    stepped = f"stepped;Src={CF}:Source;Dbl={CF}:Doubler"
    pipe, hello = hosts.ready("--composite", stepped, name="Steps")
    loop = {"id": "loop", "out": "Src.out", "to": to(hello), "in": "Dbl.inp", "policy": {}}
    assert pipe.command("connect", conn=loop)["ok"] is True
    assert pipe.command("activate")["ok"] is True
    assert pipe.command("step", n=4)["ok"] is True
    beat = pipe.wait_for(
        lambda m: m["t"] == "heartbeat" and m["ports"]["Src.out"]["frames_out"] >= 4,
        what="4 frames out of Src",
    )
    assert beat["ports"]["Src.out"]["frames_out"] == 4  # four steps, four writes, no clock
    # the link to our own address is in process: each value Src writes is in Dbl's queue
    # before Dbl runs in the same step, so Dbl has passed on all four
    assert beat["ports"]["Src.out"]["frames_sent"] == 4
    assert beat["ports"]["Dbl.inp"]["frames_in"] == 4
    assert beat["ports"]["Dbl.out"]["frames_out"] == 4
    assert pipe.command("repoint", conn_id="loop", to="tcp://127.0.0.1:9")["ok"] is False
    assert beat.get("data", {}).get("accepted", 0) == 0  # nothing went through the data server
    assert pipe.command("exit")["ok"] is True
    assert pipe.wait_exit() == 0
