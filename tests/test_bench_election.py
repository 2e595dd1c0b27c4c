"""The election benchmark's smoke test: `--quick --json` runs and writes every figure."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_quick_bench_writes_every_figure(tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "bench_election.py"), "--quick", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "Failover" in done.stdout
    figures = json.loads(out.read_text())
    assert figures["quick"] is True
    assert figures["config"]["preset"] == "lan"
    (cell,) = figures["failover"]
    assert cell["n"] == 10
    assert cell["failed"] == 0
    assert cell["deaths"] == len(cell["known_by_all_s"]) >= 2
    assert 0 < cell["detected_median_s"] <= cell["claimed_median_s"]
    assert cell["claimed_median_s"] <= cell["known_by_all_median_s"] <= cell["known_by_all_p90_s"]
    assert cell["known_by_all_p90_s"] < 5.0
