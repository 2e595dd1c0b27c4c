"""The data-plane benchmark's smoke test: `--quick --json` runs and writes every figure."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _positive(value: object) -> bool:
    return isinstance(value, int | float) and math.isfinite(value) and value > 0


def test_quick_bench_writes_every_figure(tmp_path: Path) -> None:
    out = tmp_path / "bench.json"
    done = subprocess.run(
        [sys.executable, str(ROOT / "tools" / "bench_dataplane.py"), "--quick", "--json", str(out)],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    assert "Targets" in done.stdout
    figures = json.loads(out.read_text())
    assert figures["quick"] is True
    small = {"sdrpeer_tcp", "sdrpeer_tcp_acked", "sdrpeer_tcp_inport", "sdrpeer_unix", "zmq"}
    small |= {"plain_tcp", "sdrpeer_tcp_acked_enc"}
    typed = {"sdrpeer_tcp_acked_typed", "zmq_typed"}
    assert set(figures["small"]) == small | {"plain_tcp_coalesced"} | typed
    assert set(figures["big"]) == small | {"sdrpeer_shm"}
    rtt = {"sdrpeer_tcp", "sdrpeer_service", "plain_tcp", "zmq", "asyncio_raw"}
    assert set(figures["rtt"]) == rtt
    for section in ("small", "big"):
        for name, cell in figures[section].items():
            assert _positive(cell["median"]), (section, name)
            assert len(cell["runs"]) == figures["reps"] == 1
    for name, cell in figures["rtt"].items():
        assert 0 < cell["p50_us"] <= cell["p99_us"], name
    assert len(figures["targets"]) == 11  # 7 of the data plane, 2 of encryption, loss, service
    names = [t["target"] for t in figures["targets"]]
    assert "service call p50 <= 1.5x data-port RTT" in names
    for target in figures["targets"]:
        assert _positive(target["ratio"]) if "ratio" in target else target["silent"] >= 0
        assert isinstance(target["met"], bool)
    (loss,) = figures["loss"]
    assert 0 < loss["taken"] < loss["frames"] == 5000  # the consumer is slower than its producer
    assert loss["dropped_at_receiver_told"] == loss["dropped_at_receiver_counted"] > 0
    assert loss["silent"] == 0  # every frame not taken was counted where it was sent
    cpu = figures["cpu_per_gb"]
    assert set(cpu) == {"sdrpeer_tcp_acked", "sdrpeer_tcp_acked_enc"}
    for cell in cpu.values():
        assert _positive(cell["median"])
        assert _positive(cell["ceiling_mb_s"])
    # CPU time, not wall time: sealing and opening every byte costs more whatever the load
    assert cpu["sdrpeer_tcp_acked_enc"]["median"] > cpu["sdrpeer_tcp_acked"]["median"]
