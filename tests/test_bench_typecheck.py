"""tools/bench_typecheck.py runs the real `sdrpeer system check` on pairs of port kinds and counts
what it refuses; here each sender against three receivers (--quick), and the rule it judges by."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))

from bench_typecheck import should_refuse  # noqa: E402


def test_the_rule_a_pair_is_judged_by() -> None:
    assert should_refuse("Pose", "Image")
    assert should_refuse("Pose", "MyPose")  # another name, the same fields
    assert should_refuse("Pose", "OldPose")  # the same name, another layout
    assert not should_refuse("Pose", "Pose")
    assert not should_refuse("Pose", "Any")
    assert not should_refuse("Any", "Image")
    assert should_refuse("PlanA", "PlanA2")  # the same name, another method set
    assert should_refuse("PlanA", "Any")  # a service port bound to a data port
    assert not should_refuse("PlanB", "PlanB")


def test_quick_run_refuses_every_mismatched_pair_and_accepts_the_rest(tmp_path: Path) -> None:
    out = tmp_path / "typecheck.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "bench_typecheck.py"), "--quick", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
        cwd=ROOT,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    doc = json.loads(out.read_text())
    assert doc["pairs"] == 12 * 3
    assert doc["mismatched"] + doc["matching"] == doc["pairs"]
    assert doc["refused"] == doc["mismatched"] > 0
    assert doc["accepted"] == doc["matching"] > 0
    assert doc["wrong"] == []
