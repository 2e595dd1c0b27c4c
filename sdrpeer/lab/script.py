"""A scenario's lab steps carried out on a running lab: agent deaths, stops, restarts, partitions
and heals (`sdrpeer lab up --scenario FILE`).

How it works: the agents run their own robots' steps (set, ramp, move); the steps that act on a
robot from outside (`Scenario.lab_steps()`) are run here, by whoever started the agents.
`LabScript` is the pure part: `due(t)` hands out each step whose `at` has come, once and in
order, and `next_at()` says when the next one is. `Conductor` is its shell over a `RunningLab`:
`tick()` reads the wall clock once, measures it from the lab's time 0 (lab.json's `created`,
which every agent also gets as `--scenario-start`: one clock for all steps) and does each due
step for real:
- `agent: kill`: SIGKILL to the robot's agent process; its component hosts die with it (their
  parent-death signal): what a robot's death is. It waits, bounded, until the process is gone.
- `agent: stop`: SIGTERM: the agent leaves the fleet gracefully and stops its hosts.
- `agent: restart`: the same agent again (its data dir, key and token, joining a running robot;
  `RunningLab.restart`), its new addresses recorded in lab.json once it has written them.
- `partition`: iptables DROP rules by source address between the groups, in every robot's
  network namespace (`NetPlan.partition`): datagrams really lost, both ways; robots in no group
  keep hearing everyone. Only a namespace lab (`--netns`) has the network for it: `check` refuses
  a scenario with one for a lab on loopback before anything starts.
- `heal`: every partition and fault removed (`NetPlan.heal`).
Each step done is said (`say`) and kept in `done` with the lab time it ran at.
"""

from __future__ import annotations

import signal
import subprocess
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from sdrpeer.errors import ScenarioError, SdrpeerError
from sdrpeer.lab.files import robot_name
from sdrpeer.lab.up import RunningLab
from sdrpeer.monitor.scenario import Scenario, Step
from sdrpeer.netlab import net

STOP_WAIT = 10.0
"""How long a kill or stop waits for the agent process to be gone (s)."""
START_WAIT = 30.0
"""How long a restart waits for the agent to write its addresses (s)."""


def lab_steps(path: Path) -> list[Step]:
    """The lab steps of a scenario file (ScenarioError with file:line on a bad one)."""
    return Scenario.load(path).lab_steps()


def check(steps: Sequence[Step], robots: int, *, netns: bool, where: str) -> None:
    """Refuse steps this lab cannot carry out: an unknown robot, or a partition or heal in a lab
    without namespaces. `where` names the scenario file in the error."""
    known = {robot_name(i) for i in range(1, robots + 1)}
    for step in steps:
        named = [step.robot] if step.robot else []
        named += [r for group in step.values.get("groups", ()) for r in group]
        unknown = sorted(set(named) - known)
        if unknown:
            raise ScenarioError(
                f"{where}:{step.line}: {step.kind}: unknown robot {unknown[0]!r} "
                f"(this lab has {', '.join(sorted(known))})"
            )
        if step.kind in ("partition", "heal") and not netns:
            raise ScenarioError(
                f"{where}:{step.line}: {step.kind}: needs the namespace lab's network "
                "(sdrpeer lab up --netns, as root); a lab on loopback cannot drop packets"
            )


class LabScript:
    """Which lab steps are due (pure: the caller gives the time)."""

    def __init__(self, steps: Sequence[Step]) -> None:
        self._steps = sorted(steps, key=lambda s: s.at)
        self._next = 0

    def due(self, t: float) -> list[Step]:
        """The steps with `at` <= t not handed out before, in order."""
        out = []
        while self._next < len(self._steps) and self._steps[self._next].at <= t:
            out.append(self._steps[self._next])
            self._next += 1
        return out

    def next_at(self) -> float | None:
        """When the next step is due (None: none left)."""
        return self._steps[self._next].at if self._next < len(self._steps) else None


def describe_step(step: Step) -> str:
    """A step in a person's words."""
    if step.kind == "agent":
        return f"{step.robot}: agent {step.values['agent']}"
    if step.kind == "partition":
        return "partition " + " / ".join(",".join(g) for g in step.values["groups"])
    return "heal"


class Conductor:
    """Carries out a lab's scenario steps on time (see the module docstring)."""

    def __init__(
        self,
        running: RunningLab,
        steps: Sequence[Step],
        *,
        say: Callable[[str], None] = print,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.running = running
        self.script = LabScript(steps)
        self.say = say
        self.clock = clock
        self.origin = running.lab.created
        """Wall time of the scenario's time 0 (the agents' too)."""
        self.done: list[tuple[float, str]] = []
        """(lab time, what) of every step carried out."""

    def elapsed(self) -> float:
        """Seconds since the scenario's time 0."""
        return self.clock() - self.origin

    def next_in(self) -> float | None:
        """Seconds until the next step (0 when one is due; None when none is left)."""
        at = self.script.next_at()
        return None if at is None else max(0.0, at - self.elapsed())

    def tick(self) -> list[str]:
        """Carry out every step due now; what was done."""
        t = self.elapsed()
        out = []
        for step in self.script.due(t):
            what = f"{describe_step(step)} ({self.do(step)})"
            self.done.append((round(t, 3), what))
            self.say(f"scenario {t:.1f}s: {what}")
            out.append(what)
        return out

    def run_until(self, t_end: float, *, sleep: Callable[[float], None] = time.sleep) -> None:
        """Carry out the steps up to lab time `t_end` (bounded: returns at `t_end`)."""
        while True:
            self.tick()
            left = t_end - self.elapsed()
            if left <= 0:
                return
            wait = self.next_in()
            sleep(min(left, 0.5 if wait is None else max(0.01, min(wait, 0.5))))

    def do(self, step: Step) -> str:
        """One step, for real; how it went."""
        if step.kind == "agent":
            action = step.values["agent"]
            if action == "restart":
                return self._restart(step.robot)
            sig = signal.SIGKILL if action == "kill" else signal.SIGTERM
            return self._signal(step.robot, sig)
        plan = self.running.net
        if plan is None:  # `check` refuses this before the lab starts
            raise SdrpeerError(f"{describe_step(step)}: this lab has no namespace network")
        if step.kind == "partition":
            net.run(plan.partition(step.values["groups"]))
            return "packets between the groups dropped"
        net.run(plan.heal(), check=False)
        return "no partition, no fault"

    def _signal(self, name: str, sig: signal.Signals) -> str:
        proc = self.running.process(name)
        if proc is None or proc.poll() is not None:
            return "its agent was not running"
        proc.send_signal(sig)
        try:
            proc.wait(timeout=STOP_WAIT)
        except subprocess.TimeoutExpired:
            return f"pid {proc.pid} still running {STOP_WAIT:g} s after {sig.name}"
        return f"pid {proc.pid} {sig.name}, exit {proc.returncode}"

    def _restart(self, name: str) -> str:
        proc = self.running.process(name)
        if proc is not None and proc.poll() is None:
            return "its agent is running: nothing to restart"
        self.running.restart(name)
        self.running.wait_started(name, START_WAIT)
        new = self.running.process(name)
        return f"pid {None if new is None else new.pid}"
