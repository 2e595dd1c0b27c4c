"""The host benchmark's composite comparison runs and writes its figures (how small a composite
is, is measured by tools/bench_host.py --composite 5, not asserted here)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def test_the_composite_comparison_writes_both_sides_and_the_ratio(tmp_path: Path) -> None:
    out = tmp_path / "host.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "bench_host.py"),
            "--composite",
            "2",
            "--runs",
            "1",
            "--idle",
            "0.2",
            "--target",
            "tests.components_fixture:Counter",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stderr
    assert "ratio composite / separate" in done.stdout
    doc = json.loads(out.read_text())
    assert doc["members"] == 2
    (separate,) = doc["separate_rss_bytes"]
    (composite,) = doc["composite_rss_bytes"]
    assert separate > 0
    assert composite > 0
    assert doc["ratio"] == composite / separate
