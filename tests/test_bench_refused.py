"""The refused-sender benchmark runs and writes its figures (how fast the agent hears a refusal
and a blocked host exits is measured by tools/bench_refused.py, not asserted here); the host it
stops exits cleanly."""

from __future__ import annotations

from pathlib import Path

from tests.benchrun import run_bench


def test_the_refused_sender_benchmark_writes_its_figures(tmp_path: Path) -> None:
    out, doc = run_bench("bench_refused", tmp_path / "refused.json", "--runs", "1")
    assert "refused -> agent (s)" in out
    (run,) = doc["runs"]
    assert "proof does not hold" in run["error"]
    assert run["exit_code"] == 0
    assert doc["exit_codes"] == [0]
    assert doc["refused_to_agent_max_s"] >= 0
    assert doc["exit_max_s"] >= 0
