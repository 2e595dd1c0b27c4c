"""tools/fuzz.py on every surface, briefly: random and mutated inputs are refused with the
surface's own error and counted, never a crash; valid-looking ones still get through."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def fuzz(tmp_path: Path, inputs: int, surfaces: str) -> dict[str, dict[str, Any]]:
    """Run tools/fuzz.py on `surfaces` (comma-separated); its figures by surface."""
    out = tmp_path / "fuzz.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "fuzz.py"), "--inputs", str(inputs), "--seed", "7",
         "--only", surfaces, "--json", str(out)],
        capture_output=True, text=True, timeout=300, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stdout + done.stderr
    return {r["surface"]: r for r in json.loads(out.read_text())}


def test_every_surface_survives_random_and_mutated_inputs(tmp_path: Path) -> None:
    results = fuzz(tmp_path, 3000, "gossip,control,stream")
    assert set(results) == {"gossip", "control", "stream"}
    for name, r in results.items():
        assert r["crashes"] == 0, (name, r["crash_samples"])
        assert r["accepted"] + r["refused"] == r["inputs"] == 3000
        assert r["refused"] > 0, name  # the random third at least
        assert r["accepted"] > 0, name  # mutations that stay valid reach the code behind
        assert sum(r["refused_by_reason"].values()) >= r["refused"] > 0, name
    assert results["gossip"]["refused_by_reason"]["malformed"] > 0
    assert results["stream"]["refused_by_reason"]["malformed"] > 0


def test_the_yaml_loaders_survive_hostile_and_mutated_files(tmp_path: Path) -> None:
    results = fuzz(tmp_path, 600, "system,robot,scenario")
    assert set(results) == {"system", "robot", "scenario"}
    for name, r in results.items():
        assert r["crashes"] == 0, (name, r["crash_samples"])
        assert r["accepted"] + r["refused"] == r["inputs"] == 600
        assert r["accepted"] > 0, name  # tree mutations that stay valid load
        assert r["refused_by_reason"]["not valid YAML"] > 0, name  # the snippets are refused


def test_the_http_routes_never_answer_5xx(tmp_path: Path) -> None:
    r = fuzz(tmp_path, 600, "http")["http"]
    assert r["crashes"] == 0, r["crash_samples"]
    assert r["accepted"] > 0  # valid bodies change the robot
    assert {"400", "404"} <= set(r["refused_by_reason"])
