"""Paths in system files resolve against the file, are checked, and reach the robots resolved."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import psutil
import pytest

from sdrpeer.cli.main import main
from sdrpeer.errors import SystemFileError
from sdrpeer.system.loader import load_system, parse_system
from tests.realnet import RealCluster, http

SCRIPT = '''\
"""A component run by the `script` launcher from a file next to the system file."""

from sdrpeer.sdk import Component, OutPort, Periodic


class Ticker(Component):
    """Publishes 1, 2, 3, ... at 20 Hz."""

    execution = Periodic(hz=20)
    out = OutPort("the count")

    def on_initialize(self) -> None:
        """Start from zero."""
        self.n = 0

    def on_execute(self) -> None:
        """Publish the next number."""
        self.n += 1
        self.out.write(self.n)
'''


def project(root: Path, components: str) -> Path:
    """A system file in root/proj with a script in root/proj/nodes; the file's path."""
    (root / "proj" / "nodes").mkdir(parents=True)
    (root / "proj" / "nodes" / "ticker.py").write_text(SCRIPT)
    (root / "proj" / "bin").mkdir()
    (root / "proj" / "bin" / "driver").write_text("#!/bin/sh\n")
    path = root / "proj" / "system.yaml"
    path.write_text("name: paths\ncomponents:\n" + textwrap.dedent(components))
    return path


def test_a_script_and_an_exec_program_resolve_against_the_file_not_the_cwd(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = project(
        tmp_path,
        """\
          - {name: T, launcher: script, target: "nodes/ticker.py:Ticker"}
          - {name: U, launcher: script, target: nodes/../nodes/ticker.py}
          - {name: D, launcher: exec, target: [./bin/driver, --fast, data/x]}
          - {name: P, launcher: exec, target: [driver-on-path, -v]}
          - {name: A, launcher: exec, target: [/usr/bin/not-checked-here]}
        """,
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    proj = (tmp_path / "proj").resolve()
    s = load_system(os.path.relpath(path))
    assert s.component("T").target == f"{proj / 'nodes' / 'ticker.py'}:Ticker"
    assert s.component("U").target == str(proj / "nodes" / "ticker.py")
    assert s.component("D").target == (str(proj / "bin" / "driver"), "--fast", "data/x")
    assert s.component("P").target == ("driver-on-path", "-v")  # each robot's PATH
    assert s.component("A").target == ("/usr/bin/not-checked-here",)  # installed on the robots
    # what a deploy sends, hence what the plan carries to every robot
    sent = {c["name"]: c["target"] for c in s.to_json()["components"]}
    assert sent["T"] == f"{proj / 'nodes' / 'ticker.py'}:Ticker"


def test_parse_system_resolves_against_its_base_dir(tmp_path: Path) -> None:
    project(tmp_path, "  - {name: T, launcher: script, target: nodes/ticker.py}\n")
    text = "name: t\ncomponents: [{name: T, launcher: script, target: nodes/ticker.py}]\n"
    s = parse_system(text, "inline.yaml", base_dir=tmp_path / "proj")
    assert s.component("T").target == str((tmp_path / "proj" / "nodes" / "ticker.py").resolve())


def test_a_missing_file_is_named_with_file_line_and_field(tmp_path: Path) -> None:
    path = project(
        tmp_path,
        """\
          - {name: T, launcher: script, target: "nodes/tickr.py:Ticker"}
          - {name: D, launcher: exec, target: [bin/drivr]}
          - {name: N, launcher: script, target: nodes}
        """,
    )
    proj = (tmp_path / "proj").resolve()
    with pytest.raises(SystemFileError) as info:
        load_system(path)
    assert str(info.value).splitlines() == [
        f"{path}: 3 problems",
        f"{path}:3: field 'components[0].target': no such file 'nodes/tickr.py':"
        f" looked for {proj / 'nodes' / 'tickr.py'} (relative to {proj})",
        f"{path}:4: field 'components[1].target': no such file 'bin/drivr':"
        f" looked for {proj / 'bin' / 'drivr'} (relative to {proj})",
        f"{path}:5: field 'components[2].target': 'nodes' is not a file: {proj / 'nodes'}",
    ]


def test_system_check_reports_a_missing_script_and_exits_2(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = project(tmp_path, "  - {name: T, launcher: script, target: nodes/gone.py}\n")
    assert main(["system", "check", str(path)]) == 2
    err = capsys.readouterr().err
    assert f"{path}:3: field 'components[0].target': no such file 'nodes/gone.py'" in err
    (tmp_path / "proj" / "nodes" / "gone.py").write_text(SCRIPT)
    assert main(["system", "check", "--json", str(path)]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert doc["components"][0]["target"] == str((tmp_path / "proj/nodes/gone.py").resolve())


@pytest.mark.realnet
def test_an_agent_elsewhere_runs_the_script_the_system_file_names(
    cluster: RealCluster, tmp_path: Path
) -> None:
    """`sdrpeer deploy` typed in a third directory: the agent (its working directory is the
    cluster's) starts the script next to the system file, ACTIVE, with the resolved path."""
    agent = cluster.start("robot-1", flags=["--allow-launcher", "script"])
    path = project(tmp_path, '  - {name: T, launcher: script, target: "nodes/ticker.py:Ticker"}\n')
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    argv = [sys.executable, "-m", "sdrpeer", "deploy", os.path.relpath(path, elsewhere), "--wait"]
    done = subprocess.run(
        [*argv, "--timeout", "60", "--api", agent.api, "--token", agent.token],
        cwd=elsewhere,
        capture_output=True,
        text=True,
        timeout=90,
        check=False,
    )
    assert done.returncode == 0, done.stderr + done.stdout
    assert "all 1 components ACTIVE" in done.stdout
    script = f"{(tmp_path / 'proj' / 'nodes' / 'ticker.py').resolve()}:Ticker"
    status, plan = http("GET", agent.api + "/v1/plan", token=agent.token)
    assert status == 200, plan
    assert plan["plan"]["system"]["components"][0]["target"] == script
    row = next(r for r in agent.get("/v1/instances") if r["component"] == "T")
    assert script in psutil.Process(row["pid"]).cmdline()  # the host the agent started
    cluster.wait_until(
        lambda: next(r for r in agent.get("/v1/instances") if r["component"] == "T")["ports"],
        lambda ports: ports.get("out", {}).get("frames_out", 0) > 5,
        "the script's frames",
    )
