"""The test session's leak check (tests/conftest.py): a process started with this session's mark
that outlives its module is found, waited for, killed; an agent among them is named."""

from __future__ import annotations

import os
import subprocess
import sys

from tests.conftest import SESSION_ENV, left_behind, reap_left_behind
from tests.realnet import kill_all

SLEEP = "import time; time.sleep(60)"


def test_a_left_agent_is_named_and_killed_with_everything_else() -> None:
    mark = "leak-check-test"
    env = dict(os.environ, **{SESSION_ENV: mark})
    agent = [sys.executable, "-c", SLEEP, "-m", "sdrpeer", "agent", "--name", "robot-7"]
    procs = [
        subprocess.Popen(agent, env=env, start_new_session=True),  # looks like an agent
        subprocess.Popen([sys.executable, "-c", SLEEP], env=env),  # anything else
        subprocess.Popen([sys.executable, "-c", SLEEP]),  # not marked: not ours
    ]
    try:
        assert sorted(p.pid for p in left_behind(mark)) == sorted(p.pid for p in procs[:2])
        named = reap_left_behind(mark, wait=0.5)
        assert named == [f"pid {procs[0].pid}: {' '.join(agent)}"]
        # Both are gone (psutil reaped them, so Popen cannot see the signal numbers).
        assert [p.wait(timeout=10) is not None for p in procs[:2]] == [True, True]
        assert procs[2].poll() is None
        assert left_behind(mark) == []
    finally:
        kill_all(procs)
