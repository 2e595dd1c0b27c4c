"""Test helper: a stand-in `sdrpeer.agent.main` for lab failure tests
(PYTHONPATH=tests/fake_agent).

`run_agent` exits with code 3 at once when $FAKE_AGENT_FAIL names this robot; sleeps without ever
writing its addresses (an agent still starting) when $FAKE_AGENT_HANG names it; otherwise it writes
a DATA_DIR/agent.json with made-up addresses and sleeps until it is signalled. It binds nothing:
it only exercises the lab's process, file and error handling.
"""

from __future__ import annotations

import json
import os
import sys
import time
import types
from typing import Any


def run_agent(config: Any) -> int:
    """Fail on request, else report made-up addresses and sleep."""
    if os.environ.get("FAKE_AGENT_FAIL") == config.name:
        print(f"{config.name}: failing on purpose", flush=True)
        return 3
    if os.environ.get("FAKE_AGENT_HANG") == config.name:
        while True:
            time.sleep(60)
    info = {"name": config.name, "gossip": "127.0.0.1:9", "api": "http://127.0.0.1:9", "pid": 0}
    (config.data_dir / "agent.json").write_text(json.dumps(info))
    while True:
        time.sleep(60)


_module = types.ModuleType("sdrpeer.agent.main")
_module.run_agent = run_agent  # type: ignore[attr-defined]
sys.modules["sdrpeer.agent.main"] = _module
