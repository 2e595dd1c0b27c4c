"""The simulator's fleet benchmark: `--quick --json` runs and writes every figure."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_quick_sim_fleet_bench_writes_every_figure(tmp_path: Path) -> None:
    out = tmp_path / "sim.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "bench_sim_fleet.py"), "--quick", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    doc = json.loads(out.read_text())
    assert doc["quick"] is True
    rows = {r["n"]: r for r in doc["rows"]}
    assert set(rows) == {10, 60}
    for row in rows.values():
        assert row["wire_bytes_per_s_mean"] > row["bytes_per_s_mean"] > 0
        assert row["detected"] == "2 of 2"
        assert 0 < row["detect_median_s"] <= row["detect_max_s"] < 10
    # Flat in the fleet's size: six times the robots, about the same bytes per robot.
    assert rows[60]["bytes_per_s_mean"] < 1.3 * rows[10]["bytes_per_s_mean"]
    assert rows[60]["loss_30"]["false_deaths"] == 0
