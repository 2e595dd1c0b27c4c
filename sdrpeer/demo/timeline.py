"""The demo's timeline recorder: polls every agent in a background thread, writes JSON lines.

How it works: `start()` writes a "start" line and starts one daemon thread. Every `interval`
seconds the thread asks all agents at once (a small thread pool; each call bounded by
`timeout`) for `/v1/members` and the `/v1/events` after the last id it read, hands the answers
to the pure `Collector` (sdrpeer/demo/collect.py: which lines, de-duplication, states only on
change) and appends its lines to `out`, flushed every round. An agent that fails (killed, hung)
only gives an "agent" down line; the others go on. `mark(what, label)` adds a "mark" line at
once, from any thread. `stop()` ends the thread (bounded wait) and closes the file; nothing here
raises into the caller after `start()` has opened the file. Line formats: sdrpeer/demo/collect.py
and `load_timeline`; the helpers over a loaded timeline: sdrpeer/demo/query.py (`Timeline`).
"""

from __future__ import annotations

import json
import logging
import threading
import time
from collections.abc import Callable, Mapping
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import IO, Any

from sdrpeer.client import AgentClient
from sdrpeer.demo.collect import Answer, Collector, Line
from sdrpeer.demo.query import Timeline
from sdrpeer.errors import ApiError

__all__ = ["MARKS", "Timeline", "TimelineRecorder", "load_timeline"]

log = logging.getLogger(__name__)

MARKS = ("allocation", "recovery", "fault")
"""What a mark can be: allocation and recovery are the paper's orange and purple lines."""
EVENTS_PAGE = 500
EVENTS_MAX_PAGES = 10


class TimelineRecorder:
    """Polls agents (robot -> API base URL) every `interval` s and writes `out` (JSON lines)."""

    def __init__(
        self,
        apis: Mapping[str, str],
        out: Path,
        interval: float = 0.25,
        *,
        timeout: float = 1.0,
        clock: Callable[[], float] = time.time,
    ) -> None:
        self.apis = dict(apis)
        self.out = out
        self.interval = interval
        self.clock = clock
        self._clients = {r: AgentClient(url, timeout=timeout) for r, url in self.apis.items()}
        self._join_s = 2 * timeout + interval + 1.0
        self._start = 0.0
        self._collector: Collector | None = None
        self._file: IO[str] | None = None
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.rounds = 0
        """Poll rounds done so far."""

    @property
    def started_at(self) -> float:
        """Wall-clock time of `t` = 0."""
        return self._start

    def start(self) -> None:
        """Open `out`, write the "start" line and start polling in a daemon thread."""
        if self._thread is not None:
            raise RuntimeError("the recorder was already started")
        self.out.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.out.open("w", encoding="utf-8")
        self._start = self.clock()
        self._collector = Collector(list(self.apis), self._start)
        robots = list(self.apis)
        self._write(
            [{"t": 0.0, "kind": "start", "wall": self._start, "robots": robots, "apis": self.apis}]
        )
        self._thread = threading.Thread(target=self._run, name="timeline-recorder", daemon=True)
        self._thread.start()

    def mark(self, what: str, label: str = "") -> None:
        """Add a "mark" line now (what: allocation, recovery or fault)."""
        t = round(self.clock() - self._start, 3)
        self._write([{"t": t, "kind": "mark", "what": what, "label": label}])

    def stop(self) -> None:
        """Stop polling (waits a bounded time for the last round) and close the file."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(self._join_s)
            if self._thread.is_alive():
                log.warning("timeline recorder: the last poll round did not end in time")
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None

    def __enter__(self) -> TimelineRecorder:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _run(self) -> None:
        with ThreadPoolExecutor(max(1, len(self.apis)), thread_name_prefix="timeline") as pool:
            while not self._stop.is_set():
                began = time.monotonic()
                try:
                    answers = list(pool.map(self._ask, self.apis))
                    assert self._collector is not None
                    self._write(self._collector.round(answers))
                    self.rounds += 1
                except Exception:
                    log.exception("timeline recorder: a poll round failed")
                self._stop.wait(max(0.0, self.interval - (time.monotonic() - began)))

    def _ask(self, robot: str) -> Answer:
        client = self._clients[robot]
        assert self._collector is not None
        try:
            members = client.members()
            events: list[dict[str, Any]] = []
            since = self._collector.cursor(robot)
            for _ in range(EVENTS_MAX_PAGES):
                page = client.events(since=since, limit=EVENTS_PAGE)
                events.extend(page)
                if len(page) < EVENTS_PAGE or not isinstance(page[-1].get("id"), int):
                    break
                since = page[-1]["id"]
        except (ApiError, OSError, ValueError, TypeError, AttributeError) as exc:
            return Answer(robot, self.clock(), error=str(exc))
        return Answer(robot, self.clock(), members=members, events=events)

    def _write(self, lines: list[Line]) -> None:
        if not lines:
            return
        with self._lock:
            if self._file is None:
                return
            try:
                for line in lines:
                    self._file.write(json.dumps(line, separators=(",", ":")) + "\n")
                self._file.flush()
            except (OSError, TypeError, ValueError):
                log.exception("timeline recorder: cannot write %s", self.out)


def load_timeline(path: Path) -> list[dict[str, Any]]:
    """The lines of a timeline.jsonl in time order (a torn or malformed line is skipped)."""
    lines: list[dict[str, Any]] = []
    with path.open(encoding="utf-8") as f:
        for text in f:
            try:
                line = json.loads(text)
            except json.JSONDecodeError:
                continue
            if isinstance(line, dict) and isinstance(line.get("t"), int | float):
                lines.append(line)
    lines.sort(key=lambda line: line["t"])
    return lines
