"""A scenario's lab steps on real labs: `agent: kill` SIGKILLs a robot's agent (the fleet sees it
dead), `agent: restart` brings the same robot back (alive again, new process), `agent: stop`
makes it leave; in a namespace lab `partition` really cuts the network and `heal` mends it.
`sdrpeer lab up` runs the steps itself and refuses them with --detach or without --netns."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from sdrpeer.client import AgentClient
from sdrpeer.errors import ApiError
from sdrpeer.lab.procs import processes_naming as lab_survivors
from sdrpeer.lab.script import Conductor
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.monitor.scenario import Scenario, Step
from tests.realnet import NETNS_ONLY, REPO
from tests.wait import until

pytestmark = pytest.mark.realnet
WITHIN, POLL = 30.0, 0.2


def states(lab: RunningLab, robot: str) -> dict[str, str]:
    api = lab.lab.robot(robot).api  # type: ignore[union-attr]
    return {m["name"]: m["state"] for m in AgentClient(str(api), timeout=2).members()}


def step(lab: RunningLab, text: str) -> Step:
    """One lab step due a second from now (lab time), parsed as a scenario file has it."""
    at = time.time() - lab.lab.created + 1.0
    (only,) = Scenario.parse(f"steps:\n  - {{at: {at:.2f}s, {text}}}\n").lab_steps()
    return only


def run(lab: RunningLab, s: Step) -> tuple[float, str]:
    """Carry out `s` on time with a conductor; (lab time it ran at, what it did)."""
    conductor = Conductor(lab, [s], say=lambda _: None)
    conductor.run_until(s.at + 0.05)
    (done,) = conductor.done
    return done


def test_agent_kill_restart_and_stop_act_on_the_real_processes(tmp_path: Path) -> None:
    lab = start_lab(UpOptions(3, tmp_path / "lab", preset="lan", timeout=60), say=lambda _: None)
    try:
        old = lab.process("robot-3")
        assert old is not None

        kill = step(lab, "robot: robot-3, agent: kill")
        at, what = run(lab, kill)
        assert at >= kill.at
        assert what == f"robot-3: agent kill (pid {old.pid} SIGKILL, exit -9)"
        assert old.poll() == -9
        until(
            "robot-3 dead as robot-1 sees it",
            lambda: states(lab, "robot-1"),
            lambda s: s["robot-3"] == "dead",
            within=WITHIN,
            poll=POLL,
            retry=(ApiError,),
        )

        at, what = run(lab, step(lab, "robot: robot-3, agent: restart"))
        new = lab.process("robot-3")
        assert new is not None
        assert new.pid != old.pid
        assert new.poll() is None
        assert what == f"robot-3: agent restart (pid {new.pid})"
        assert lab.lab.robot("robot-3").pid == new.pid  # type: ignore[union-attr]
        for name in ("robot-1", "robot-3"):  # robot-3 answers on its new address
            until(
                f"robot-3 alive again as {name} sees it",
                lambda name=name: states(lab, name),  # type: ignore[misc]
                lambda s: s["robot-3"] == "alive" and set(s.values()) == {"alive"},
                within=WITHIN,
                poll=POLL,
                retry=(ApiError,),
            )

        two = lab.process("robot-2")
        assert two is not None
        _, what = run(lab, step(lab, "robot: robot-2, agent: stop"))
        assert what == f"robot-2: agent stop (pid {two.pid} SIGTERM, exit 0)"
        until(
            "robot-2 left",
            lambda: states(lab, "robot-1"),
            lambda s: s.get("robot-2") in ("left", None),
            within=WITHIN,
            poll=POLL,
            retry=(ApiError,),
        )
        _, what = run(lab, step(lab, "robot: robot-2, agent: kill"))
        assert what == "robot-2: agent kill (its agent was not running)"
    finally:
        lab.stop(grace=3)


@NETNS_ONLY
def test_partition_and_heal_cut_and_mend_a_namespace_labs_network(tmp_path: Path) -> None:
    lab = start_lab(
        UpOptions(3, tmp_path / "lab", preset="lan", netns=True, timeout=60), say=lambda _: None
    )
    try:
        _, what = run(lab, step(lab, "partition: [[robot-1], [robot-2, robot-3]]"))
        assert what == "partition robot-1 / robot-2,robot-3 (packets between the groups dropped)"
        until(
            "cut, as robot-1 sees it",
            lambda: states(lab, "robot-1"),
            lambda s: s["robot-2"] == s["robot-3"] == "dead",
            within=WITHIN,
            poll=POLL,
            retry=(ApiError,),
        )
        assert states(lab, "robot-2")["robot-3"] == "alive"  # inside a side nothing changes
        _, what = run(lab, step(lab, "heal: true"))
        assert what == "heal (no partition, no fault)"
        for name in ("robot-1", "robot-2", "robot-3"):
            until(
                f"healed, as {name} sees it",
                lambda name=name: states(lab, name),  # type: ignore[misc]
                lambda s: set(s.values()) == {"alive"},
                within=WITHIN,
                poll=POLL,
                retry=(ApiError,),
            )
    finally:
        lab.stop(grace=3)


def sdrpeer(*args: str, timeout: float = 90) -> subprocess.CompletedProcess[str]:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    return subprocess.run(
        [sys.executable, "-m", "sdrpeer", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
        env=env,
        check=False,
    )


def test_lab_up_refuses_lab_steps_it_cannot_run_before_starting_anything(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        "steps:\n  - {at: 5s, robot: robot-2, agent: kill}\n  - {at: 9s, heal: true}\n"
    )
    lab_dir = tmp_path / "lab"
    detached = sdrpeer(
        "lab", "up", "--robots", "2", "--dir", str(lab_dir), "--scenario", str(scenario),
        "--detach", "--netns",
    )  # fmt: skip
    assert detached.returncode != 0
    assert "leave out --detach" in detached.stderr
    loopback = sdrpeer(
        "lab", "up", "--robots", "2", "--dir", str(lab_dir), "--scenario", str(scenario)
    )
    assert loopback.returncode != 0
    assert f"{scenario}:3: heal: needs the namespace lab's network" in loopback.stderr
    assert not (lab_dir / "lab.json").exists()  # nothing was started


def test_lab_up_in_the_foreground_carries_out_the_steps(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text("steps:\n  - {at: 1s, robot: robot-2, agent: kill}\n")
    done = sdrpeer(
        "lab", "up", "--robots", "2", "--preset", "lan", "--dir", str(tmp_path / "lab"),
        "--scenario", str(scenario), "--seconds", "4", "--timeout", "60",
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    assert "robot-2: agent kill (pid" in done.stdout
    assert "SIGKILL, exit -9)" in done.stdout


def test_lab_up_refuses_a_scenario_step_for_a_robot_it_does_not_have(tmp_path: Path) -> None:
    """A `set` step for robot-9 in a 2-robot lab: no agent would ever run it (each knows only
    its own robot), so `lab up` refuses the file, naming file, line and robot, and starts
    nothing."""
    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        "steps:\n  - {at: 1s, robot: robot-1, set: {battery: 50%}}\n"
        "  - {at: 2s, robot: robot-9, set: {battery: 40%}}\n"
    )
    lab_dir = tmp_path / "lab"
    done = sdrpeer(
        "lab", "up", "--robots", "2", "--dir", str(lab_dir), "--scenario", str(scenario),
        "--detach",
    )  # fmt: skip
    try:
        assert done.returncode == 2  # a configuration error
        assert done.stderr.strip() == (
            f"error: {scenario}:3: field 'robot': unknown robot 'robot-9' (known: robot-1, robot-2)"
        )
        assert not (lab_dir / "lab.json").exists()  # nothing was started
        assert lab_survivors(lab_dir) == []
    finally:
        if (lab_dir / "lab.json").exists():  # a lab that did start must not outlive the test
            sdrpeer("lab", "down", "--dir", str(lab_dir))
