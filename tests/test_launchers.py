"""Launchers: built-in argv, target checks, unknown names, plugins from entry points."""

from __future__ import annotations

import json
import sys
from typing import Any

import pytest

from sdrpeer.errors import LauncherError
from sdrpeer.launch import launchers
from sdrpeer.launch.launchers import Launcher, get_launcher, host_env, known_launchers, param_arg
from sdrpeer.launch.policy import LaunchPolicy

PY = "/usr/bin/python3"


@pytest.mark.parametrize(
    ("value", "text"),
    [(True, "true"), (False, "false"), (10, "10"), (0.1, "0.1"), (1e300, "1e+300"), ("a b", "a b")],
)
def test_param_arg(value: Any, text: str) -> None:
    assert param_arg(value) == text


def test_python_launcher_argv() -> None:
    argv = get_launcher("python").command("pkg.mod:Cam", {"rate": 5, "b": True}, python=PY)
    assert argv == [
        PY,
        "-m",
        "sdrpeer.host",
        "pkg.mod:Cam",
        "--param",
        "b=true",
        "--param",
        "rate=5",
    ]


@pytest.mark.parametrize("target", ["pkg.mod", "file.py:Cam", ":Cam", "pkg:", ["a"], ""])
def test_python_launcher_rejects(target: Any) -> None:
    with pytest.raises(LauncherError, match="'python'"):
        get_launcher("python").command(target, {}, python=PY)


@pytest.mark.parametrize("target", ["dir/cam.py", "dir/cam.py:Cam", "/abs/x.py"])
def test_script_launcher_argv(target: str) -> None:
    argv = get_launcher("script").command(target, {"n": "x"}, python=PY)
    assert argv == [PY, "-m", "sdrpeer.host", target, "--param", "n=x"]


@pytest.mark.parametrize("target", ["pkg.mod:Cam", "dir/cam", ["cam.py"]])
def test_script_launcher_rejects(target: Any) -> None:
    with pytest.raises(LauncherError, match="'script'"):
        get_launcher("script").command(target, {}, python=PY)


def test_exec_launcher_is_the_argv_itself() -> None:
    argv = ["/opt/cam/bin/cam", "--fast"]
    out = get_launcher("exec").command(argv, {"rate": 1}, python=PY)
    assert out == argv
    assert out is not argv


@pytest.mark.parametrize("target", ["cam", [], ["cam", ""], [1]])
def test_exec_launcher_rejects(target: Any) -> None:
    with pytest.raises(LauncherError, match="'exec'"):
        get_launcher("exec").command(target, {}, python=PY)


def test_unknown_launcher_lists_known() -> None:
    with pytest.raises(LauncherError) as info:
        get_launcher("docker")
    assert "unknown launcher 'docker'" in str(info.value)
    assert "exec, openrtm, python, ros2, script" in str(info.value)
    assert {"exec", "python", "script"} <= set(known_launchers())


def test_builtins_satisfy_the_protocol() -> None:
    for name in ("python", "script", "exec"):
        launcher = get_launcher(name)
        assert isinstance(launcher, Launcher)
        assert launcher.name == name


class _Nix:
    """A plugin launcher for the test."""

    name = "nix"

    def command(self, target: str | list[str], params: dict[str, Any], *, python: str) -> list[str]:
        """Run the target in a nix shell."""
        return ["nix-shell", "--run", str(target)]


class _EntryPoint:
    """Just enough of importlib.metadata.EntryPoint."""

    def __init__(self, name: str, obj: object) -> None:
        self.name = name
        self.value = f"tests.test_launchers:{name}"
        self._obj = obj

    def load(self) -> object:
        """The object the entry point names."""
        if isinstance(self._obj, Exception):
            raise self._obj
        return self._obj


def test_plugins_from_entry_points(monkeypatch: pytest.MonkeyPatch) -> None:
    eps = {
        "nix": _EntryPoint("nix", _Nix),
        "broken": _EntryPoint("broken", ImportError("no module named nixpkgs")),
        "bogus": _EntryPoint("bogus", object()),
        "python": _EntryPoint("python", _Nix),
    }
    monkeypatch.setattr(launchers.LAUNCHERS, "_points", lambda: eps)
    monkeypatch.setattr(launchers.LAUNCHERS, "_loaded", {})
    assert get_launcher("nix").command("x", {}, python=PY) == ["nix-shell", "--run", "x"]
    assert get_launcher("python").name == "python"  # built-ins win
    with pytest.raises(LauncherError, match=r"'broken'.*failed to load: no module named nixpkgs"):
        get_launcher("broken")
    with pytest.raises(LauncherError, match=r"launcher 'bogus' is a object, not a Launcher"):
        get_launcher("bogus")
    known = "known: bogus, broken, composite, exec, nix, openrtm, python, script"
    with pytest.raises(LauncherError, match=known):
        get_launcher("other")


def test_real_entry_point_discovery_does_not_fail() -> None:
    assert "python" in known_launchers()
    assert get_launcher("python").command("a.b:C", {}, python=sys.executable)[0] == sys.executable


def test_host_env() -> None:
    env = host_env(instance="Cam1", control_fd=7, data_host="10.0.0.2", run_dir="/run/x")
    assert env == {
        "SDRPEER_CONTROL_FD": "7",
        "SDRPEER_INSTANCE": "Cam1",
        "SDRPEER_DATA_HOST": "10.0.0.2",
        "SDRPEER_RUN_DIR": "/run/x",
    }
    env = host_env(instance="C", control_fd=3, data_host="h", run_dir="/r", params={"b": 1})
    assert json.loads(env["SDRPEER_PARAMS"]) == {"b": 1}


def test_composite_launcher() -> None:
    target = "stepped;A=a.b:C;B=a.b:D"
    argv = get_launcher("composite").command(target, {"B.on": True, "A.rate": 2.5}, python=PY)
    assert argv[:5] == [PY, "-m", "sdrpeer.host", "--composite", target]
    assert argv[5:] == ["--param", "A.rate=2.5", "--param", "B.on=true"]
    with pytest.raises(LauncherError, match="at least one member"):
        get_launcher("composite").command("periodic:5", {}, python=PY)


def test_a_composite_runs_where_python_does_each_member_held_to_allow_targets() -> None:
    target = "stepped;Cam=components.camera:Camera;Spy=evil.mod:Spy"
    assert LaunchPolicy().refusal("composite", target) is None  # python, any module
    narrow = LaunchPolicy(targets=("components.*",))
    why = narrow.refusal("composite", target)
    assert why is not None
    assert why.startswith("composite member Spy: python target 'evil.mod:Spy'")
    assert narrow.refusal("composite", "stepped;Cam=components.camera:Camera") is None
    no_python = LaunchPolicy(launchers=("exec",))
    assert "launcher 'composite' is off" in (no_python.refusal("composite", target) or "")
    only_composites = LaunchPolicy(launchers=("composite",), targets=("components.*",))
    why = only_composites.refusal("composite", target)  # allowed by name, members still held
    assert why is not None
    assert why.startswith("composite member Spy: python target 'evil.mod:Spy'")
    assert only_composites.refusal("composite", "stepped;Cam=components.camera:Camera") is None
