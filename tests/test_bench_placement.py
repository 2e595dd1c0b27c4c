"""The placement benchmark's smoke test: `--quick --json` runs and writes every figure."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_quick_bench_writes_every_figure(tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "bench_placement.py"), "--quick", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "first_fit" in done.stdout
    assert "objective" in done.stdout
    figures = json.loads(out.read_text())
    assert figures["quick"] is True
    assert figures["config"]["components"] == 100
    assert [r["strategy"] for r in figures["results"]] == ["first_fit", "objective"]
    for row in figures["results"]:
        assert row["feasible"] is True
        assert row["placements"] == 100
        assert row["median_s"] > 0
        assert row["per_s"] > 0
        assert len(row["runs_s"]) == figures["config"]["runs"]
        assert row["target_per_s"] == 10_000
