"""PoseSink: counts the `Pose` frames it takes and how old each is, for tools/bench_ros2.py.

Every quarter of a second of input (and at finalize) it appends one JSON line to the file `out`:
`{"t": wall time, "n": frames taken so far, "lat": [now - frame stamp, ms, per frame since the
last line]}`; a bench reads the count's rate and the latencies from those lines. The stamp is the
frame's own (a bridged ROS 2 message's header.stamp), so latencies need one clock: a bench on one
machine."""

from __future__ import annotations

import json
import time

from sdrpeer.sdk import Component, InPort, NoData, OnInput, Param
from sdrpeer.sdk.robot_types import Pose

FLUSH_S = 0.25


class PoseSink(Component):
    """Takes every Pose; writes its count and latencies to `out`."""

    execution = OnInput("pose")
    pose = InPort("poses to count", type=Pose)
    out = Param(str, "", "the JSON-lines file to append to")

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.taken = 0
        self._lat: list[float] = []
        self._flushed = time.time()

    def on_execute(self) -> None:
        port = self.inport("pose")
        lat = self._lat
        while True:
            try:
                p: Pose = port.get_nowait()
            except NoData:
                break
            now = time.time()
            self.taken += 1
            lat.append(round((now - p.stamp) * 1e3, 4))
        if time.time() - self._flushed >= FLUSH_S:
            self._flush()

    def _flush(self) -> None:
        path = str(self.param_values()["out"])
        self._flushed = now = time.time()
        if path:
            with open(path, "a", encoding="utf-8") as f:
                f.write(json.dumps({"t": now, "n": self.taken, "lat": self._lat}) + "\n")
        self._lat = []

    def on_finalize(self) -> None:
        self._flush()
