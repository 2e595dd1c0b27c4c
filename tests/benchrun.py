"""Run one of tools/'s benchmarks as a user would, for the tests that check it runs: its exit
code, what it printed and the figures it wrote with --json."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def run_bench(tool: str, json_path: Path, *args: str, timeout: float = 120) -> tuple[str, Any]:
    """(stdout, the --json figures) of `tools/<tool>.py ARGS --json json_path`; AssertionError
    with its stderr when it fails."""
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / f"{tool}.py"), *args, "--json", str(json_path)],
        capture_output=True,
        text=True,
        timeout=timeout,
        check=False,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout, json.loads(json_path.read_text())
