"""Record a real camera to MCAP, read it back, replay it into a consumer: frame-exact?

Usage: python tools/bench_record.py [--frames 300] [--rate 100] [--size 320x240]
                                    [--speed 0] [--keep DIR] [--json out.json]

How it works: a one-robot lab (a real agent with a cluster key, so every data stream is
authenticated) runs the paper's camera (`components.camera:Camera`, `--rate` Hz, `--size`
grayscale pixels) and a `components.ledger:FrameLedger` consumer that writes the msgpack bytes
of every value it takes to a file. `sdrpeer port record Cam.image --count N` (the same code,
`sdrpeer.cli.port.record`) records `--frames` frames through the agent's tap to an MCAP file;
the file is then opened with `mcap.reader.make_reader` (channels, schema, messages); `sdrpeer
port replay --map Cam.image=Sink.inp --speed S` (`sdrpeer.cli.port.replay`) feeds it into the
consumer. Printed: frames recorded, read back, replayed and identical (the consumer's bytes,
in order, equal to the recording's), frames the camera numbered but the recording lacks (the
tap fell behind), the rate the recording kept up with (frames/s and MB/s, from the first to
the last frame's receive time) and the replay's rate.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import msgpack

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mcap.reader import make_reader  # noqa: E402

from components.ledger import read_frames  # noqa: E402
from sdrpeer.cli.port import RECORD_POLICY, record, replay  # noqa: E402
from sdrpeer.client import AgentClient, wait_for  # noqa: E402
from sdrpeer.lab.up import UpOptions, start_lab  # noqa: E402


def states(client: AgentClient) -> dict[str, str]:
    return {i["name"]: i["state"] for i in client.get("/v1/instances")}


def measure(args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    width, _, height = args.size.partition("x")
    sink_dir = tmp / "sink"
    running = start_lab(UpOptions(1, tmp / "lab", preset="lan", timeout=60), say=lambda _: None)
    try:
        robot = running.lab.robots[0]
        client = AgentClient(str(robot.api), robot.token, timeout=10)
        cam = {
            "name": "Cam",
            "target": "components.camera:Camera",
            "params": {"rate": args.rate, "width": int(width), "height": int(height)},
        }
        sink = {
            "name": "Sink",
            "target": "components.ledger:FrameLedger",
            "params": {"dir": str(sink_dir)},
        }
        client.post("/v1/instances", {"instances": [cam, sink]})
        wait_for(
            lambda: states(client),
            lambda s: s == {"Cam": "ACTIVE", "Sink": "ACTIVE"},
            "Cam and Sink ACTIVE",
            60,
        )
        out = tmp / "cam.mcap"
        body = {"count": args.frames, "policy": RECORD_POLICY}
        done = record(client, ["Cam.image"], out, body)
        with out.open("rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            assert summary is not None
            topics = sorted(c.topic for c in summary.channels.values())
            schemas = sorted(f"{s.name} ({s.encoding})" for s in summary.schemas.values())
            recorded = [m.data for _, _, m in reader.iter_messages(log_time_order=False)]
        seqs = [msgpack.unpackb(d)["seq"] for d in recorded]
        missing = (seqs[-1] - seqs[0] + 1 - len(seqs)) if seqs else 0
        fed = replay(client, out, {"Cam.image": "Sink.inp"}, args.speed)
        kept = wait_for(
            lambda: read_frames(str(sink_dir)) if sink_dir.exists() else [],
            lambda frames: len(frames) >= len(recorded),
            "the replayed frames at Sink",
            60,
        )
        identical = sum(1 for a, b in zip(recorded, kept, strict=False) if a == b)
        in_order = kept[: len(recorded)] == recorded
    finally:
        running.stop(grace=3)
    span = (done["last_ns"] - done["first_ns"]) / 1e9
    frames_per_span = (len(recorded) - 1) / span if span > 0 else 0.0
    return {
        "camera_rate_hz": args.rate,
        "frame_bytes": int(width) * int(height),
        "frames_asked": args.frames,
        "frames_recorded": done["frames"],
        "frames_read": len(recorded),
        "frames_replayed": int(fed["answer"]["frames"]),
        "frames_identical": identical,
        "identical_in_order": in_order,
        "frames_missing_in_recording": missing,
        "tap_dropped": int(done["end"].get("dropped", 0)),
        "topics": topics,
        "schemas": schemas,
        "record_fps": round(frames_per_span, 1),
        "record_mb_s": round(frames_per_span * len(recorded[0]) / 1e6, 2) if recorded else 0.0,
        "file_mb": round(out.stat().st_size / 1e6, 2),
        "replay_speed": args.speed,
        "replay_s": round(fed["seconds"], 3),
        "replay_fps": round(len(recorded) / fed["seconds"], 1) if fed["seconds"] > 0 else 0.0,
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--frames", type=int, default=300, help="frames to record")
    p.add_argument("--rate", type=float, default=100.0, help="camera frames per second")
    p.add_argument("--size", default="320x240", help="camera WIDTHxHEIGHT (grayscale)")
    p.add_argument("--speed", type=float, default=0.0, help="replay speed (0: at once)")
    p.add_argument("--keep", type=Path, metavar="DIR", help="keep the lab and files in DIR")
    p.add_argument("--json", type=Path, help="also write the figures to this file")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        tmp = args.keep or Path(scratch)
        tmp.mkdir(parents=True, exist_ok=True)
        r = measure(args, tmp)
    print(f"camera {args.size} at {r['camera_rate_hz']:g} Hz ({r['frame_bytes']} B a frame)")
    print(f"  recording: {', '.join(r['topics'])}; schemas {', '.join(r['schemas'])}")
    print(
        f"  frames recorded {r['frames_recorded']}, read {r['frames_read']}, replayed "
        f"{r['frames_replayed']}, identical {r['frames_identical']} "
        f"(in order: {r['identical_in_order']})"
    )
    print(
        f"  missing in the recording {r['frames_missing_in_recording']} "
        f"(tap dropped {r['tap_dropped']})"
    )
    print(
        f"  recording kept up with {r['record_fps']} frames/s, {r['record_mb_s']} MB/s "
        f"(file {r['file_mb']} MB)"
    )
    print(f"  replay at speed {r['replay_speed']:g}: {r['replay_s']} s, {r['replay_fps']} frames/s")
    print("target: identical == recorded, in order")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(r, indent=2))
        print(f"wrote {args.json}")
    ok = r["frames_identical"] == r["frames_recorded"] and r["identical_in_order"]
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
