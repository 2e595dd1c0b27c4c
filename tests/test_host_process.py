"""The host as a process: targets, exit codes, signals, agent death, standalone mode, footprint."""

from __future__ import annotations

import ctypes
import os
import signal
import subprocess
import sys
import textwrap
from collections.abc import Callable
from pathlib import Path

import pytest

from tests.hostctl import ROOT, HostPool, measure
from tests.wait import until

FX = "tests.components_fixture"
HEAVY = ("aiohttp", "prometheus_client", "yaml", "psutil", "hashlib", "hmac", "cryptography")
"""What a host never imports unless it needs it (hashlib and hmac load OpenSSL: +4 MB idle RSS
when the key derivations imported them at the top of sdrpeer.keys.derive)."""


def wait_log(path: Path, text: str, timeout: float = 5.0) -> str:
    """The log once it contains `text` (WaitError with its tail after `timeout`)."""
    return until(
        f"{text!r} in {path.name}",
        lambda: path.read_text(errors="replace"),
        lambda content: text in content,
        within=timeout,
    )


@pytest.mark.parametrize(
    ("target", "message"),
    [
        ("no_such_pkg.mod:Cam", "no module named 'no_such_pkg'"),
        (f"{FX}:Nope", "defines no 'Nope'"),
        (f"{FX}:ROOT", "defines no 'ROOT'"),
        ("tests.hostctl:HostProc", "HostProc is not a subclass of Component"),
        (
            FX,
            "defines several Component subclasses "
            "(Counter, Crasher, EchoCaller, EchoService, Faulty, Fragile, Hoarder, Laggard,"
            " Recorder, Reporter, Sleeper, Stubborn, Tally, Tunable)",
        ),
        ("tests/no_such_file.py", "no such file"),
        ("tests/hostctl.py", "defines no subclass of Component"),
    ],
)
def test_bad_target_exits_2_with_a_clear_message(
    hosts: HostPool, target: str, message: str
) -> None:
    host = hosts.spawn(target)
    assert host.wait_exit() == 2
    log = host.log_text()
    assert f"cannot load {target}" in log
    assert message in log


def test_target_that_raises_on_import_shows_its_traceback(hosts: HostPool, tmp_path: Path) -> None:
    bad = tmp_path / "broken.py"
    bad.write_text("import math\n\nraise ValueError('no camera attached')\n")
    host = hosts.spawn(str(bad))
    assert host.wait_exit() == 2
    log = host.log_text()
    assert "raised ValueError: no camera attached" in log
    assert 'broken.py", line 3' in log


def test_script_target_with_and_without_class(hosts: HostPool, tmp_path: Path) -> None:
    script = tmp_path / "cam.py"
    script.write_text(
        textwrap.dedent(
            """
            from sdrpeer.sdk import Component, OutPort
            from tests.components_fixture import Counter  # imported, not defined here

            class Cam(Component):
                image = OutPort()
            """
        )
    )
    for target in (str(script), f"{script}:Cam"):
        host, hello = hosts.ready(target, name=f"cam{len(hosts.hosts)}")
        assert hello["component"] == "Cam"
        assert hello["ports"] == {"in": [], "out": ["image"]}
        assert host.command("exit")["ok"] is True
        assert host.wait_exit() == 0


def test_host_exits_when_the_agent_closes_the_channel(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter")
    host.command("activate")
    host.sock.close()
    assert host.wait_exit(5.0) == 0
    log = host.log_text()
    assert "the agent closed the control channel" in log
    assert "state FINALIZED" in log  # nobody left to tell, but it finalized


def test_sigterm_under_the_agent_finalizes_and_exits_0(hosts: HostPool) -> None:
    host, _ = hosts.ready(f"{FX}:Counter")
    host.command("activate")
    host.proc.send_signal(signal.SIGTERM)
    host.wait_state("FINALIZED")
    assert host.wait_exit() == 0


def test_host_dies_with_its_parent(tmp_path: Path) -> None:
    """An agent killed with SIGKILL: its host must not live on."""
    pid_file = tmp_path / "host.pid"
    agent = textwrap.dedent(
        f"""
        import sys, time
        from pathlib import Path
        sys.path.insert(0, {str(ROOT)!r})
        from tests.hostctl import HostProc
        host = HostProc.spawn({FX + ":Counter"!r}, run_dir=Path({str(tmp_path)!r}))
        host.wait_state("INACTIVE", 10)
        Path({str(pid_file)!r}).write_text(str(host.proc.pid))
        time.sleep(60)
        """
    )
    parent = subprocess.Popen([sys.executable, "-c", agent], cwd=ROOT)
    try:
        until("the host's pid file", pid_file.exists, within=10)
        host_pid = int(pid_file.read_text())
        parent.kill()
        parent.wait(5)
        until("the host gone with its agent", lambda: not _alive(host_pid), within=10)
    finally:
        parent.kill()
        parent.wait(5)
        if pid_file.exists() and _alive(int(pid_file.read_text())):
            os.kill(int(pid_file.read_text()), signal.SIGKILL)


def _alive(pid: int) -> bool:
    """True if `pid` runs and is not a zombie."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().split(") ")[1][0] != "Z"
    except (FileNotFoundError, IndexError):
        return False


def test_standalone_activates_reports_and_exits_on_sigterm(tmp_path: Path) -> None:
    log = tmp_path / "standalone.log"
    env = {k: v for k, v in os.environ.items() if not k.startswith("SDRPEER_")}
    env["PYTHONPATH"] = str(ROOT)
    with open(log, "wb") as err:
        proc = subprocess.Popen(
            [sys.executable, "-X", "importtime", "-m", "sdrpeer.host", f"{FX}:Counter"],
            stdout=err,
            stderr=err,
            env=env,
            cwd=ROOT,
        )
    try:
        wait_log(log, "state ACTIVE")
        text = wait_log(log, "ports out: frames_out=", 10.0)
        unix = text.split("'unix': '")[1].split("'")[0]
        assert os.path.exists(unix)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(5) == 0
        text = log.read_text()
        assert "state FINALIZED" in text
        assert not os.path.exists(os.path.dirname(unix))  # its temporary run dir is gone
        imported = {line.split("|")[-1].strip() for line in text.splitlines() if "|" in line}
        assert not {m for m in imported if m.split(".")[0] in HEAVY}
    finally:
        proc.kill()
        proc.wait(5)


def test_standalone_exits_on_sigint(tmp_path: Path) -> None:
    log = tmp_path / "standalone.log"
    with open(log, "wb") as err:
        proc = subprocess.Popen(
            [sys.executable, "-m", "sdrpeer.host", f"{FX}:Recorder", "--name", "R"],
            stdout=err,
            stderr=err,
            cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)},
        )
    try:
        wait_log(log, "state ACTIVE")
        proc.send_signal(signal.SIGINT)
        assert proc.wait(5) == 0
        assert "state FINALIZED" in log.read_text()
    finally:
        proc.kill()
        proc.wait(5)


def test_footprint(tmp_path: Path) -> None:
    """A host reaches INACTIVE and stays small (no heavy imports crept in).

    How fast and how small is measured by tools/bench_host.py (targets: 150 ms, 25 MB); this test
    asserts behaviour only, with a memory guard well above the target so a loaded machine or
    another Python build cannot make it flaky.
    """
    _, rss_kib = measure(f"{FX}:Counter", tmp_path, idle=0.5)  # fails unless it reaches INACTIVE
    assert rss_kib / 1024 <= 35.0, f"idle RSS {rss_kib / 1024:.1f} MiB: a heavy import crept in?"


_GET_PDEATHSIG = """
import ctypes, sys
sys.path.insert(0, sys.argv[1])
from sdrpeer.control.host_side import arm_parent_death_signal
assert arm_parent_death_signal()
value = ctypes.c_int(0)
ctypes.CDLL(None).prctl(2, ctypes.byref(value), 0, 0, 0)
print(value.value)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="prctl is Linux-only")
def test_parent_death_signal_is_sigterm_unless_the_agent_armed_one() -> None:
    def run(preexec: Callable[[], None] | None = None) -> int:
        out = subprocess.run(
            [sys.executable, "-c", _GET_PDEATHSIG, str(ROOT)],
            capture_output=True,
            check=True,
            timeout=10,
            preexec_fn=preexec,
        )
        return int(out.stdout)

    def agent_arms_sigkill() -> None:
        ctypes.CDLL(None).prctl(1, signal.SIGKILL, 0, 0, 0)

    assert run() == signal.SIGTERM
    assert run(agent_arms_sigkill) == signal.SIGKILL
