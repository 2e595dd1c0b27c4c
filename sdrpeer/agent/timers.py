"""The agent's own timers (not its parts'), with presets like the other layers' configurations.

Every duration is in seconds. An agent takes these from the preset its `--preset` names
(`sdrpeer.agent.tuning`). How often it samples its robot is a flag, not a preset value
(`--metrics-interval`, `sdrpeer.config.AgentConfig.metrics_interval`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any


@dataclass(frozen=True, slots=True)
class AgentTimers:
    """Tunables of the agent itself. Use a preset (`lan()`, `fast_test()`) and `with_()`."""

    record_gap: float = 1.0
    """A measured value crossing a threshold makes a new record at most once per this long;
    a crossing sooner goes out as vitals until then (`sdrpeer.monitor.publish.Publisher`)."""
    leave_wait: float = 0.3
    """After its leave message a stopping agent keeps its gossip socket open this long, so the
    message is spread and retransmitted (about three `lan` gossip rounds)."""
    stop_deadline: float = 2.5
    """A graceful stop (leave, the component hosts' on_finalize, closing the API) may take this
    long; past it the agent SIGKILLs its hosts and exits with 1, saying what it waited for."""

    def __post_init__(self) -> None:
        for name in ("record_gap", "leave_wait", "stop_deadline"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"agent {name} must be >= 0 (got {getattr(self, name)!r})")

    def with_(self, **changes: Any) -> AgentTimers:
        """A copy with some fields changed."""
        return replace(self, **changes)


def lan() -> AgentTimers:
    """Robots on one Wi-Fi network."""
    return AgentTimers()


def lab() -> AgentTimers:
    """Many agents on one busy machine: the `lan` timers."""
    return AgentTimers()


def fast_test() -> AgentTimers:
    """Loopback tests and the local lab: so far the `lan` timers (a leave still needs a few
    rounds to spread, and a stop the same time to finish)."""
    return AgentTimers()
