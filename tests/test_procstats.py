"""The process-tree meter: a robot's measured CPU and memory, reused for `max_age` seconds."""

from __future__ import annotations

import os
import subprocess
import sys

from sdrpeer.monitor.procstats import ProcessTreeMeter


def test_a_measurement_younger_than_max_age_is_answered_again() -> None:
    # An agent samples on every instance change: finding the tree reads all of /proc, and a
    # CPU share over a few milliseconds swings 0-100 %. Time is injected.
    t = [0.0]
    meter = ProcessTreeMeter(os.getpid(), include_root=False, max_age=1.0, clock=lambda: t[0])
    before = meter.measure()
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        t[0] = 0.5
        assert meter.measure() == before  # the child is not looked for yet
        t[0] = 1.5
        _, rss = meter.measure()
        assert rss > before[1]  # measured again: the child's memory counts
    finally:
        child.kill()
        child.wait(10)


def test_without_max_age_every_call_measures() -> None:
    meter = ProcessTreeMeter(os.getpid(), include_root=False, clock=lambda: 0.0)
    before = meter.measure()
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(30)"])
    try:
        assert meter.measure()[1] > before[1]
    finally:
        child.kill()
        child.wait(10)
