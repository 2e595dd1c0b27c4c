"""The wheel: built from this tree (`pip wheel`), installed into a fresh virtualenv away from the
source tree, it runs: `sdrpeer --version`, `sdrpeer keygen`, `sdrpeer systemd-unit` and an
agent that starts (its API answers) and stops cleanly on SIGTERM."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
import urllib.request
from pathlib import Path

import pytest

import sdrpeer
from sdrpeer.keys.keyring import Keyring

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.slow


def run(argv: list[str], cwd: Path, timeout: float = 600) -> str:
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "VIRTUAL_ENV")}
    done = subprocess.run(
        argv, capture_output=True, text=True, timeout=timeout, check=False, cwd=cwd, env=env
    )
    assert done.returncode == 0, f"{argv}: {done.stdout}\n{done.stderr}"
    return done.stdout


SKIP = shutil.ignore_patterns(
    ".venv*",
    ".git",
    "out",
    "build",
    "dist",
    "*.egg-info",
    "__pycache__",
    ".*_cache",
    ".sdrpeer-lab",
)


def test_the_wheel_installs_into_a_clean_venv_and_runs(tmp_path: Path) -> None:
    source, dist = tmp_path / "src", tmp_path / "dist"
    shutil.copytree(ROOT, source, ignore=SKIP, ignore_dangling_symlinks=True)  # built in place
    run([sys.executable, "-m", "pip", "wheel", "--no-deps", "-w", str(dist), str(source)], tmp_path)
    wheels = list(dist.glob("sdrpeer-*.whl"))
    assert len(wheels) == 1, wheels
    venv = tmp_path / "venv"
    run([sys.executable, "-m", "venv", str(venv)], tmp_path)
    python, exe = venv / "bin" / "python", venv / "bin" / "sdrpeer"
    run([str(python), "-m", "pip", "install", str(wheels[0])], tmp_path)
    # it runs from the venv, not from this tree
    where = run([str(python), "-c", "import sdrpeer; print(sdrpeer.__file__)"], tmp_path)
    assert where.startswith(str(venv)), where
    assert run([str(exe), "--version"], tmp_path).strip() == f"sdrpeer {sdrpeer.__version__}"
    key_file = tmp_path / "cluster.key"
    key_file.write_text(run([str(exe), "keygen"], tmp_path))
    assert len(Keyring.from_file(key_file).signing_key) == 32
    unit = run([str(exe), "systemd-unit", "--config", str(tmp_path / "agent.yaml")], tmp_path)
    assert f"ExecStart={python} -m sdrpeer agent" in unit
    # an agent from the wheel, configured by a file only; the dashboard's files are packaged
    data = tmp_path / "data"
    config = tmp_path / "agent.yaml"
    config.write_text(
        f"name: wheel-1\nbind: 127.0.0.1:0\napi: 127.0.0.1:0\nkey-file: {key_file}\n"
        f"data-dir: {data}\npreset: fast_test\n"
    )
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    log = tmp_path / "agent.log"
    with log.open("wb") as out:
        agent = subprocess.Popen(
            [str(exe), "agent", "--config", str(config)],
            cwd=tmp_path,
            env=env,
            stdout=out,
            stderr=subprocess.STDOUT,
        )
    try:
        deadline = time.monotonic() + 60
        info = None
        while time.monotonic() < deadline and agent.poll() is None:
            try:
                info = json.loads((data / "agent.json").read_text())
                break
            except (OSError, ValueError):
                time.sleep(0.1)
        assert info is not None, log.read_text()
        with urllib.request.urlopen(str(info["api"]) + "/", timeout=10) as page:
            assert b"<html" in page.read().lower()
    finally:
        agent.send_signal(signal.SIGTERM)
        code = agent.wait(timeout=30)
    assert code == 0, log.read_text()
