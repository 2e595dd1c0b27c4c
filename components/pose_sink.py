"""PoseSink: counts the `Pose` frames it takes and how old each is, for tools/bench_ros2.py.

Every quarter of a second of input, before a frame that follows a pause of as long, and at
finalize, it appends one JSON line to the file `out`: `{"t": when the last of its frames was
taken, "n": frames taken so far, "lat": [taken - frame stamp, ms, per frame since the last
line]}`; a bench reads the count's rate and the latencies from those lines (the line before a
pause keeps its own time, so one run's last frames never count in the next). The stamp is the
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
        self._flushed = self._last = time.time()

    def on_execute(self) -> None:
        port = self.inport("pose")
        while True:
            try:
                p: Pose = port.get_nowait()
            except NoData:
                break
            now = time.time()
            if self._lat and now - self._last >= FLUSH_S:  # a pause: what came before is a line
                self._flush()
            self.taken += 1
            self._lat.append(round((now - p.stamp) * 1e3, 4))
            self._last = now
        if self._lat and time.time() - self._flushed >= FLUSH_S:
            self._flush()

    def _flush(self) -> None:
        path = str(self.param_values()["out"])
        self._flushed = time.time()
        if path:
            with open(path, "a", encoding="utf-8") as f:
                f.write(json.dumps({"t": self._last, "n": self.taken, "lat": self._lat}) + "\n")
        self._lat = []

    def on_finalize(self) -> None:
        self._flush()
