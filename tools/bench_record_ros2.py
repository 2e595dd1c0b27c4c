"""Record a typed 50 Hz Odometry stream in ROS 2 format for 30 s: does every message decode
with rclpy?

Usage: python tools/bench_record_ros2.py [--seconds 30] [--rate 50] [--keep DIR] [--json out.json]

How it works: a one-robot lab (a real agent with a cluster key: every data stream is
authenticated) runs `components.odometry:OdometrySource` at `--rate` Hz. `sdrpeer port record
Odom.odom --format ros2 --duration S` (the same code, `sdrpeer.cli.port.record`) records it
through the agent's tap of the typed port, the path a bridged ROS 2 system's recording takes.
The file is then read with `mcap.reader` and every message given to rclpy's
`rclpy.serialization.deserialize_message` as `nav_msgs/msg/Odometry` (the ROS 2 wheels' own
type support; no DDS, no `rclpy.init`). Printed: messages recorded and decoded by rclpy, the
tap's sequence numbers missing (frames the recording lost), stamps in order, the recorded rate
and the file's size.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from mcap.reader import make_reader  # noqa: E402

from sdrpeer.cli.port import RECORD_POLICY, record  # noqa: E402
from sdrpeer.client import AgentClient, wait_for  # noqa: E402
from sdrpeer.lab.up import UpOptions, start_lab  # noqa: E402


def decode_all(path: Path) -> dict[str, Any]:
    """Every message of the recording through rclpy: how many decoded, and what they say."""
    from nav_msgs.msg import Odometry  # noqa: PLC0415 - needs the ROS 2 wheels
    from rclpy.serialization import deserialize_message  # noqa: PLC0415 - needs them too

    decoded = failed = 0
    seqs: list[int] = []
    stamps: list[float] = []
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        schemas = sorted(f"{s.name} ({s.encoding})" for s in summary.schemas.values())
        channels = sorted(f"{c.topic} ({c.message_encoding})" for c in summary.channels.values())
        for _, _, message in reader.iter_messages(log_time_order=False):
            try:
                msg = deserialize_message(message.data, Odometry)
            except Exception:  # counted: the figure is how many decode
                failed += 1
                continue
            decoded += 1
            seqs.append(message.sequence)
            stamps.append(msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9)
    missing = (seqs[-1] - seqs[0] + 1 - len(seqs)) if seqs else 0
    return {
        "decoded": decoded,
        "failed": failed,
        "missing": missing,
        "stamps_in_order": stamps == sorted(stamps),
        "span_s": (stamps[-1] - stamps[0]) if stamps else 0.0,
        "schemas": schemas,
        "channels": channels,
    }


def measure(args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    running = start_lab(UpOptions(1, tmp / "lab", preset="lan", timeout=60), say=lambda _: None)
    try:
        robot = running.lab.robots[0]
        client = AgentClient(str(robot.api), robot.token, timeout=10)
        odom = {
            "name": "Odom",
            "target": "components.odometry:OdometrySource",
            "params": {"rate": args.rate},
        }
        client.post("/v1/instances", {"instances": [odom]})
        wait_for(
            lambda: {i["name"]: i["state"] for i in client.get("/v1/instances")},
            lambda s: s == {"Odom": "ACTIVE"},
            "Odom ACTIVE",
            60,
        )
        out = tmp / "odom.mcap"
        body = {"duration": args.seconds, "policy": RECORD_POLICY}
        done = record(client, ["Odom.odom"], out, body, "ros2")
    finally:
        running.stop(grace=3)
    decoded = decode_all(out)
    return {
        "rate_hz": args.rate,
        "seconds": args.seconds,
        "recorded": done["frames"],
        **decoded,
        "tap_dropped": int(done["end"].get("dropped", 0)),
        "recorded_hz": round((decoded["decoded"] - 1) / decoded["span_s"], 2)
        if decoded["span_s"] > 0
        else 0.0,
        "file_kb": round(out.stat().st_size / 1e3, 1),
        "when": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }


def main(argv: list[str] | None = None) -> int:
    """Measure, print, and exit 1 unless every message recorded decoded."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--seconds", type=float, default=30.0, help="how long to record")
    p.add_argument("--rate", type=float, default=50.0, help="odometry messages per second")
    p.add_argument("--keep", type=Path, metavar="DIR", help="keep the lab and the file in DIR")
    p.add_argument("--json", type=Path, help="also write the figures to this file")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as scratch:
        tmp = args.keep or Path(scratch)
        tmp.mkdir(parents=True, exist_ok=True)
        r = measure(args, tmp)
    print(f"Odometry at {r['rate_hz']:g} Hz recorded {r['seconds']:g} s in ROS 2 format")
    print(f"  channels {', '.join(r['channels'])}; schemas {', '.join(r['schemas'])}")
    print(
        f"  messages recorded {r['recorded']}, decoded by rclpy {r['decoded']}, failed "
        f"{r['failed']}; missing seqs {r['missing']} (tap dropped {r['tap_dropped']})"
    )
    print(
        f"  stamps in order: {r['stamps_in_order']}; {r['recorded_hz']} msg/s over "
        f"{r['span_s']:.1f} s; file {r['file_kb']} kB"
    )
    print("target: decoded == recorded, failed 0")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(r, indent=2))
    return 0 if r["decoded"] == r["recorded"] and r["failed"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
