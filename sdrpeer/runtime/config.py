"""How a supervisor runs its host, with presets like the other layers' configurations.

Every duration is in seconds. An agent takes these from the preset its `--preset` names
(`sdrpeer.agent.tuning`), with `data_host` set from its `--bind` address.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

from sdrpeer.runtime.backoff import RestartConfig
from sdrpeer.runtime.handoff import MAX_STATE


@dataclass(frozen=True, slots=True)
class SupervisorConfig:
    """Tunables of an instance supervisor. Use a preset (`lan()`, `fast_test()`) and `with_()`."""

    restart: RestartConfig = field(default_factory=RestartConfig)
    """Restart backoff of a host that died unasked."""
    command_timeout: float = 5.0
    """How long a command waits for its reply."""
    hello_timeout: float = 15.0
    """A host that has not said hello this long after spawning is killed."""
    exit_timeout: float = 5.0
    """After the exit command, SIGTERM follows this much later."""
    term_timeout: float = 3.0
    """After SIGTERM, SIGKILL follows this much later."""
    data_host: str = "127.0.0.1"
    """SDRPEER_DATA_HOST: the address hosts bind their TCP data servers to."""
    max_state: int = MAX_STATE
    """Bytes a state may take in snapshot/restore (msgpack); bigger ones are refused."""
    max_faults: int = 16
    """How many of the last faults an instance keeps (shown in its status)."""
    heartbeat_timeout: float = 2.0
    """A host silent this long once initialized (no heartbeat: stopped, deadlocked, stuck in
    on_execute or in C code) is killed as hung; an instance's `watchdog_s` overrides it (0: off).
    Hosts send a heartbeat every 0.5 s."""
    watchdog_confirm: float = 0.25
    """A host found silent past its deadline is looked at again this much later before it is
    killed (its heartbeats may be waiting unread while the agent's loop was busy)."""
    eof_grace: float = 1.0
    """A host that closed its control channel is killed if it has not exited this much later."""
    max_starting: int = 2
    """Standbys start only while fewer hosts than this are starting on this robot, and only once
    no would-be active waits to start (0: no limit); actives always start at once
    (`sdrpeer.runtime.reconciler`)."""
    host_nice: int = 5
    """Hosts run this much nicer than their agent (`nice(2)`; 0: the same priority): a robot's
    components take every cycle its agent leaves idle, and cannot starve the agent's probes,
    heartbeat reads and steps when they, or their start-ups, want more than the cores have."""

    def with_(self, **changes: Any) -> SupervisorConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)


def lan() -> SupervisorConfig:
    """Robots on one Wi-Fi network."""
    return SupervisorConfig()


def lab() -> SupervisorConfig:
    """Many agents on one busy machine: `lan`, but a host may be silent 5 s (not 2 s) before it
    is killed as hung (a host not scheduled for 2 s is no hung host)."""
    return SupervisorConfig(heartbeat_timeout=5.0)


def fast_test() -> SupervisorConfig:
    """Tests and the local lab: short restart backoff (0.05 s doubling to at most 0.4 s, stable
    after 2 s, given up after 4 fast failures) and short command, hello and stop timeouts."""
    return SupervisorConfig(
        restart=RestartConfig(initial=0.05, maximum=0.4, stable_after=2.0, max_fast_failures=4),
        command_timeout=2.0,
        hello_timeout=5.0,
        exit_timeout=1.0,
        term_timeout=1.0,
    )
