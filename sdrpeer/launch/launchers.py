"""Launchers: how an agent turns an instance spec into the command that starts its host.

How it works: a launcher is any object with a `name` and `command(target, params, *, python)`
returning an argv (docs/protocol.md, section 3). Five are built in: `python` (`pkg.mod:Class`)
and `script` (`path/to/file.py[:Class]`), both `python -m sdrpeer.host TARGET --param k=v ...`,
`composite` (several member classes in one host, sdrpeer.launch.composite), `openrtm` (an
unmodified OpenRTM-aist RTC module, `python -m sdrpeer.openrtm`, docs/openrtm.md) and `exec` (an
argv
list run as is; it must speak the control channel itself, and gets its params as
`SDRPEER_PARAMS`, a JSON map, in its environment). Plugins come from the entry point group
`sdrpeer.launchers`; each entry point loads a launcher class (instantiated with no
arguments) or instance (`LAUNCHERS`, a `sdrpeer.plugins.registry.Registry`). `get_launcher(name)`
looks in the built-ins first, then the plugins, and fails with the list of known names. `host_env`
builds the environment of docs/protocol.md for one host.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

from sdrpeer.errors import LauncherError
from sdrpeer.launch.composite import parse_composite
from sdrpeer.launch.openrtm import available as openrtm_available
from sdrpeer.launch.policy import LaunchPolicy
from sdrpeer.plugins.registry import Registry

log = logging.getLogger("sdrpeer.launch.launchers")

ENTRY_POINT_GROUP = "sdrpeer.launchers"


@runtime_checkable
class Launcher(Protocol):
    """Turns a target and params into the argv that starts a host."""

    name: str

    def command(self, target: str | list[str], params: dict[str, Any], *, python: str) -> list[str]:
        """The argv; `python` is the interpreter to run Python hosts with."""
        ...


def param_arg(value: Any) -> str:
    """A param value as the host's `--param k=v` string (the SDK converts it back)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        return repr(value)
    return str(value)


def param_args(params: Mapping[str, Any]) -> list[str]:
    """`--param k=v` for every param, in name order."""
    out: list[str] = []
    for key in sorted(params):
        out += ["--param", f"{key}={param_arg(params[key])}"]
    return out


def _str_target(launcher: str, target: str | list[str], what: str) -> str:
    """`target` if it is a non-empty string, else LauncherError."""
    if not isinstance(target, str) or not target:
        raise LauncherError(f"launcher {launcher!r}: target must be {what}, got {target!r}")
    return target


class PythonLauncher:
    """`python -m sdrpeer.host package.module:Class`."""

    name = "python"

    def command(self, target: str | list[str], params: dict[str, Any], *, python: str) -> list[str]:
        """The host command for a module target."""
        text = _str_target(self.name, target, "'package.module:Class'")
        module, sep, cls = text.partition(":")
        if not sep or not module or not cls.isidentifier() or module.endswith(".py"):
            raise LauncherError(
                f"launcher 'python': target must be 'package.module:Class', got {text!r}"
            )
        return [python, "-m", "sdrpeer.host", text, *param_args(params)]


class ScriptLauncher:
    """`python -m sdrpeer.host path/to/file.py[:Class]`."""

    name = "script"

    def command(self, target: str | list[str], params: dict[str, Any], *, python: str) -> list[str]:
        """The host command for a file target."""
        text = _str_target(self.name, target, "'path/to/file.py[:Class]'")
        path = text.rpartition(":")[0] if text.rpartition(":")[2].isidentifier() else text
        if not path.endswith(".py"):
            raise LauncherError(
                f"launcher 'script': target must be 'path/to/file.py[:Class]', got {text!r}"
            )
        return [python, "-m", "sdrpeer.host", text, *param_args(params)]


class CompositeLauncher:
    """`python -m sdrpeer.host --composite 'CONTEXT;Member=pkg.mod:Class;...'`
    (sdrpeer.launch.composite)."""

    name = "composite"

    def command(self, target: str | list[str], params: dict[str, Any], *, python: str) -> list[str]:
        """The host command for a composite target; params are `Member.param`."""
        text = _str_target(self.name, target, "'CONTEXT;Member=pkg.mod:Class;...'")
        try:
            parse_composite(text)
        except ValueError as exc:
            raise LauncherError(f"launcher 'composite': target {text!r}: {exc}") from None
        return [python, "-m", "sdrpeer.host", "--composite", text, *param_args(params)]


class ExecLauncher:
    """The executable itself; it speaks the control channel on its own."""

    name = "exec"

    def command(self, target: str | list[str], params: dict[str, Any], *, python: str) -> list[str]:
        """`target` as given (params travel in the environment, see `host_env`)."""
        if (
            not isinstance(target, list)
            or not target
            or not all(isinstance(a, str) and a for a in target)
        ):
            raise LauncherError(
                f"launcher 'exec': target must be a non-empty argv list, got {target!r}"
            )
        return list(target)


class OpenRtmLauncher:
    """`python -m sdrpeer.openrtm path/to/Module.py[:TypeName]`: an unmodified OpenRTM-aist
    RT-Component (sdrpeer.openrtm; the `openrtm` extra, sdrpeer.launch.openrtm)."""

    name = "openrtm"

    def command(self, target: str | list[str], params: dict[str, Any], *, python: str) -> list[str]:
        """The host command for an RTC module target; params are its configuration parameters."""
        text = _str_target(
            self.name, target, "'path/to/Module.py[:TypeName]' or 'package.module[:TypeName]'"
        )
        missing = openrtm_available()
        if missing is not None:
            raise LauncherError(f"launcher 'openrtm': {missing}")
        return [python, "-m", "sdrpeer.openrtm", text, *param_args(params)]

    def available(self) -> str | None:
        """None if OpenRTM-aist-Python is installed here, else why not (`offered`)."""
        return openrtm_available()


LAUNCHERS: Registry[Launcher] = Registry(
    ENTRY_POINT_GROUP, (Launcher,), "launcher", error=LauncherError
)
"""Every launcher by name: the built-ins (registered, so they win over a plugin of their name)
and the plugins of the entry point group."""
for _builtin in (PythonLauncher, ScriptLauncher, ExecLauncher, CompositeLauncher, OpenRtmLauncher):
    LAUNCHERS.register(_builtin.name, _builtin)


def known_launchers() -> list[str]:
    """Every launcher name available: built-ins and plugins."""
    return LAUNCHERS.names()


def offered(policy: LaunchPolicy) -> tuple[LaunchPolicy, dict[str, str]]:
    """`policy` less the launchers this machine cannot run (a launcher may say why with an
    `available()` method returning None or the reason, e.g. `ros2` without ROS 2 installed), and
    why each one left out cannot run. An unknown name is left in: the configuration check
    refuses those."""
    missing: dict[str, str] = {}
    for name in policy.launchers:
        try:
            probe = getattr(get_launcher(name), "available", None)
        except LauncherError:
            continue
        why = probe() if callable(probe) else None
        if why:
            missing[name] = str(why)
    if not missing:
        return policy, missing
    kept = tuple(n for n in policy.launchers if n not in missing)
    return LaunchPolicy(kept, policy.targets), missing


def get_launcher(name: str) -> Launcher:
    """The launcher called `name`; LauncherError listing the known ones if there is none."""
    return LAUNCHERS.get(name)


def host_env(
    *,
    instance: str,
    control_fd: int,
    data_host: str,
    run_dir: str,
    params: Mapping[str, Any] | None = None,
) -> dict[str, str]:
    """The environment variables docs/protocol.md gives a host (merge into os.environ)."""
    env = {
        "SDRPEER_CONTROL_FD": str(control_fd),
        "SDRPEER_INSTANCE": instance,
        "SDRPEER_DATA_HOST": data_host,
        "SDRPEER_RUN_DIR": run_dir,
    }
    if params:
        env["SDRPEER_PARAMS"] = json.dumps(dict(params), sort_keys=True)
    return env
