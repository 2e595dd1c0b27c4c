"""Paths a system file names, resolved against the file's own directory.

How it works: a system file is read on one machine (`sdrpeer system check`, `deploy`, `run`) and
its components run on others, each started by the agent of its robot in that agent's working
directory. A relative path in the file is therefore made absolute here, against the directory of
the system file (never the working directory of whoever reads it), and checked to exist; the
loaded system, and so the plan every robot receives, carries the absolute path. Which values are
paths:
- `profile:` (read here, at load time: `sdrpeer.system.profiles`);
- a `script` target `path/to/file.py[:Class]`: its file part;
- an `exec` target's program (`argv[0]`) when it names a file by a relative path with a `/`
  (`./bin/driver`, `tools/lidar`); a bare name (`lidar-driver`) is looked up on each robot's
  PATH and an absolute one is taken as written (software installed on the robots), so neither
  is checked here, and the other arguments are the program's own business.
On a real fleet the resolved path must exist on every robot that may run the component: the same
checkout or install location on each robot (docs/system-file.md, "Paths").
"""

from __future__ import annotations

from pathlib import Path

from sdrpeer.host.loader import split_target

__all__ = ["resolve_exec_target", "resolve_file", "resolve_script_target"]


def resolve_file(base_dir: Path, written: str) -> Path:
    """The absolute, normalised path of `written` (relative to `base_dir` unless absolute; no
    `~`: an agent does not expand it either); ValueError when it is not an existing file."""
    try:
        path = (base_dir / written).resolve()
    except (OSError, ValueError) as e:  # a NUL byte, a loop of links, ...
        raise ValueError(f"cannot resolve {written[:200]!r}: {e}") from None
    try:
        is_file = path.is_file()
    except OSError as e:  # a name too long, a path through a file, ...
        raise ValueError(f"cannot read {written[:200]!r}: {e.strerror}") from None
    if path.exists() and not is_file:
        raise ValueError(f"{written[:200]!r} is not a file: {path}")
    if not is_file:
        where = "" if Path(written).is_absolute() else f" (relative to {base_dir.resolve()})"
        raise ValueError(f"no such file {written[:200]!r}: looked for {path}{where}")
    return path


def resolve_script_target(base_dir: Path, target: str) -> str:
    """A `script` target with its file made absolute: `nodes/v.py:Viewer` ->
    `/abs/dir/nodes/v.py:Viewer` (ValueError when the file does not exist)."""
    where, name = split_target(target)
    path = resolve_file(base_dir, where)
    return str(path) if name is None else f"{path}:{name}"


def resolve_exec_target(base_dir: Path, argv: tuple[str, ...]) -> tuple[str, ...]:
    """An `exec` argv whose program is a relative path with a `/`, made absolute (ValueError when
    it does not exist); any other argv as given."""
    program = argv[0]
    if "/" not in program or Path(program).is_absolute():
        return argv
    return (str(resolve_file(base_dir, program)), *argv[1:])
