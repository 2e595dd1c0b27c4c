"""tools/bench_compliance.py on a namespace lab (root), --quick: one link pushed past its bound
(measured, reported, re-placed) and one noisy minute; the figures are checked for their form
and order only (speed is the tool's to measure, not a test's to assert)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.realnet import NETNS_ONLY

pytestmark = pytest.mark.realnet
ROOT = Path(__file__).resolve().parent.parent


@NETNS_ONLY
def test_quick_run_measures_each_step(tmp_path: Path) -> None:
    out = tmp_path / "compliance.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools/bench_compliance.py"), "--quick", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        check=False,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    doc = json.loads(out.read_text())
    (trial,) = doc["trials"]
    assert trial["fault_to_crossed_s"] >= 0
    assert trial["fault_to_reported_s"] >= trial["fault_to_crossed_s"]  # a sustain apart
    assert trial["reported_to_active_elsewhere_s"] >= 0
    noise = doc["noise"]
    assert noise["minutes"] == 1.0
    assert noise["moves"] >= 0
    assert noise["link_loss_measured_median"] is not None
    assert "target: crossed -> reported <= sustain + 1 s" in done.stdout
