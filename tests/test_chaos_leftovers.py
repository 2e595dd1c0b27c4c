"""The chaos soak's sweep of processes a lab left behind: kills them, spares its own callers."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

REAP = (
    "import sys, subprocess; from pathlib import Path;"
    "from sdrpeer.chaos.run import _reap_leftovers;"
    "print(_reap_leftovers(Path(sys.argv[1])))"
)
OUTER = (
    "import subprocess, sys;"
    "sys.exit(subprocess.run([sys.executable, '-c', sys.argv[1], sys.argv[2]]).returncode)"
)


def test_a_leftover_is_killed_and_the_process_that_started_the_soak_is_not(tmp_path: Path) -> None:
    lab = tmp_path / "lab"
    leftover = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)", str(lab)])
    try:
        # the soak runs under a wrapper whose command line names the lab too (`timeout 900
        # sdrpeer lab chaos --keep DIR`): the sweep must not kill its own caller
        done = subprocess.run(
            [sys.executable, "-c", OUTER, REAP, str(lab)],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert done.returncode == 0, done.stderr
        assert f"pid {leftover.pid}:" in done.stdout
        assert done.stdout.count("pid ") == 1, done.stdout
        assert leftover.wait(10) != 0  # killed
    finally:
        if leftover.poll() is None:
            leftover.kill()
            leftover.wait(10)
