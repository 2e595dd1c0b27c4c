"""What an agent lets run on its robot: the launchers it allows and the Python targets (pure).

How it works: every host an agent starts runs code chosen by whoever hands it a spec: the
operator (`POST /v1/instances`, with the agent's token) or the allocator (a plan, with the
cluster key). `python` starts an installed module's class, `script` a Python file by path, `exec`
any command line: `exec` and `script` can run anything the agent's user can, so they are off
unless the agent's configuration names them (`allow_launchers`, `--allow-launcher`: launchers
allowed besides `python`), as Nomad ships `raw_exec` disabled. `allow_targets` narrows the
`python` launcher (and `ros2`, whose targets are module classes too) to module patterns
(shell-style, matched against `package.module:Class`;
default `*`, any installed module; an empty list turns `python` off). Plugin launchers (entry
points) run only when named too. A `composite` (sdrpeer.launch.composite) runs Python classes
in one host: it runs wherever `python` does, each member's target held to `allow_targets`.

`LaunchPolicy.refusal(launcher, target)` is None when the policy lets the spec run, else the
reason, naming the setting to change. The agent checks it where a spec comes in (the API answers
403), where the coordinator applies a plan (an event, nothing runs) and again before it spawns a
host. Robots gossip their policy (`sdrpeer.record.robot`) so that the allocator never places a
component on a robot that would refuse it.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Sequence
from dataclasses import dataclass

from sdrpeer.launch.composite import parse_composite

DEFAULT_LAUNCHERS: tuple[str, ...] = ("python",)
DEFAULT_TARGETS: tuple[str, ...] = ("*",)
PYTHON_LAUNCHERS: tuple[str, ...] = ("python", "ros2")
"""Launchers whose target is an installed module's class, held to `allow_targets`."""


@dataclass(frozen=True, slots=True)
class LaunchPolicy:
    """The launchers and Python targets one agent allows."""

    launchers: tuple[str, ...] = DEFAULT_LAUNCHERS
    targets: tuple[str, ...] = DEFAULT_TARGETS
    """Shell-style patterns a `python` target (`package.module:Class`) must match one of."""

    @property
    def is_default(self) -> bool:
        """Whether this is the policy an agent has when its configuration says nothing."""
        return self.launchers == DEFAULT_LAUNCHERS and self.targets == DEFAULT_TARGETS

    def refusal(self, launcher: str, target: str | Sequence[str]) -> str | None:
        """None if a host of `launcher` running `target` may start here, else why not."""
        if launcher == "composite" and isinstance(target, str) and "python" in self.launchers:
            return self._members_refusal(target)
        if launcher not in self.launchers:
            allowed = ", ".join(self.launchers) or "none"
            extra = [n for n in self.launchers if n != "python"]
            return (
                f"launcher {launcher!r} is off on this robot (allowed: {allowed}); "
                f"enable it in the agent's configuration: allow_launchers: "
                f"[{', '.join((*extra, launcher))}] (or --allow-launcher {launcher})"
            )
        if launcher == "ros2" and isinstance(target, str) and _is_file(target):
            if "script" not in self.launchers:  # a file runs whatever it holds, as `script`
                return (
                    f"ros2 target {target!r} is a file: a file runs anything the agent's user "
                    "can, so it needs the script launcher allowed too (allow_launchers: "
                    "[ros2, script]); or name an installed module (package.module:Class)"
                )
            return None
        if launcher in PYTHON_LAUNCHERS and isinstance(target, str):
            return self._target_refusal(target, launcher)
        if launcher == "composite":  # allowed by name: its members are still python classes
            if not isinstance(target, str):
                return f"composite target {target!r}: expected a string"
            return self._members_refusal(target)
        return None

    def _target_refusal(self, target: str, launcher: str = "python") -> str | None:
        """None if the python target matches one of `targets`, else why not."""
        if any(fnmatch.fnmatchcase(target, p) for p in self.targets):
            return None
        return (
            f"{launcher} target {target!r} matches none of this robot's allow_targets "
            f"({', '.join(self.targets) or 'none'}); add a pattern to allow_targets in "
            f"the agent's configuration (or --allow-target PATTERN)"
        )

    def _members_refusal(self, target: str) -> str | None:
        """A composite runs python classes: each member's target is held to `targets`."""
        try:
            members = parse_composite(target).members
        except ValueError as exc:
            return f"composite target {target!r}: {exc}"
        for member, member_target in members:
            why = self._target_refusal(member_target)
            if why is not None:
                return f"composite member {member}: {why}"
        return None


def _is_file(target: str) -> bool:
    """Whether a python-style target names a file (`path/to/file.py[:Class]`)."""
    where = target.rpartition(":")[0] if target.rpartition(":")[2].isidentifier() else target
    return where.endswith(".py") or "/" in where


DEFAULT_POLICY = LaunchPolicy()
"""What an agent allows when its configuration says nothing: python, any installed module."""
