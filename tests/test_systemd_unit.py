"""`sdrpeer systemd-unit` writes a unit that `systemd-analyze verify` accepts, running this
installation's interpreter with the config file and data directory given."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from sdrpeer.cli.service import unit_text

ANALYZE = shutil.which("systemd-analyze")


def write_unit(tmp_path: Path, *args: str) -> Path:
    out = tmp_path / "sdrpeer.service"
    done = subprocess.run(
        [sys.executable, "-m", "sdrpeer", "systemd-unit", *args, "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return out


@pytest.mark.skipif(ANALYZE is None, reason="systemd-analyze is not installed")
@pytest.mark.parametrize("data_dir", ["/var/lib/sdrpeer", "/srv/robot data/sdrpeer"])
def test_systemd_analyze_verify_accepts_the_unit(tmp_path: Path, data_dir: str) -> None:
    config = tmp_path / "agent.yaml"
    config.write_text("name: rover-1\nkey-file: /etc/sdrpeer/cluster.key\n")
    unit = write_unit(tmp_path, "--config", str(config), "--user", "root", "--data-dir", data_dir)
    text = unit.read_text()
    assert f"ExecStart={sys.executable} -m sdrpeer agent --config {config}" in text
    assert "ExecReload=/bin/kill -HUP $MAINPID" in text
    assert ("StateDirectory=sdrpeer" in text) == data_dir.startswith("/var/lib/")
    assert "User=root" in text
    done = subprocess.run(
        [str(ANALYZE), "verify", str(unit)], capture_output=True, text=True, timeout=60, check=False
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert "sdrpeer.service" not in done.stderr, done.stderr  # no warning about our unit


@pytest.mark.skipif(ANALYZE is None, reason="systemd-analyze is not installed")
def test_verify_would_catch_a_broken_unit(tmp_path: Path) -> None:
    """The check above can fail: the same unit with a relative ExecStart is refused."""
    text = unit_text(Path("/etc/sdrpeer/agent.yaml"), user="root")
    broken = tmp_path / "sdrpeer.service"
    broken.write_text(text.replace(f"ExecStart={sys.executable}", "ExecStart=no/such/python"))
    done = subprocess.run(
        [str(ANALYZE), "verify", str(broken)],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode != 0 or "sdrpeer.service" in done.stderr


def test_bad_users_and_relative_paths_are_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="--user"):
        unit_text(Path("/etc/a.yaml"), user="Robot Admin")
    with pytest.raises(ValueError, match="absolute"):
        unit_text(Path("agent.yaml"))
    done = subprocess.run(
        [sys.executable, "-m", "sdrpeer", "systemd-unit", "--config", "rel.yaml"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 2
    assert "absolute" in done.stderr
