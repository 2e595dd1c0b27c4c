"""The gossip benchmark's smoke test: `--quick --json` runs and writes every figure."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _number(value: object) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def test_quick_bench_writes_every_figure(tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "bench_gossip.py"), "--quick", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "Convergence" in done.stdout
    assert "Sim speed" in done.stdout
    figures = json.loads(out.read_text())
    assert figures["quick"] is True
    assert all(_number(figures["config"][k]) for k in ("probe_interval", "gossip_interval"))
    assert figures["config"]["gossip_fanout"] >= 1

    cells = {(c["n"], c["loss"]) for c in figures["convergence"]}
    assert cells == {(n, loss) for n in (10, 30) for loss in (0.0, 0.1, 0.3)}
    for cell in figures["convergence"]:
        assert _number(cell["median_s"]), cell  # every record change arrived everywhere
        assert 0 < cell["median_s"] < 5.0
        assert 0 < cell["median_99_s"] <= cell["median_s"]
        assert len(cell["times_s"]) == cell["trials"] >= 1
    assert {c["n"]: c["target_s"] for c in figures["convergence"] if c["loss"] == 0}[10] == 1.0

    bandwidth = figures["bandwidth"]
    assert bandwidth["max_robot"].startswith("r")
    for key in (
        "mean_bytes_per_s",
        "max_bytes_per_s",
        "mean_datagrams_per_s",
        "max_bytes_per_s_churned",
    ):
        assert _number(bandwidth[key]), key
        assert bandwidth[key] > 0, key
    assert bandwidth["max_bytes_per_s"] >= bandwidth["mean_bytes_per_s"]
    assert bandwidth["churned"] >= 2

    detection = figures["failure_detection"]
    assert {(r["n"], r["loss"]) for r in detection} == {(10, 0.0), (10, 0.3)}
    for row in detection:
        assert row["deaths"] >= 2
        assert row["undetected"] == 0
        assert all(_number(row[k]) for k in ("mean_s", "p50_s", "p99_s"))
        assert row["p50_s"] <= row["p99_s"]
        assert row["false_deaths"] == 0

    speed = figures["sim_speed"]
    assert all(_number(speed[k]) and speed[k] > 0 for k in ("wall_s", "virtual_s", "n"))
