"""Tunables of the recovery engine that are not part of a system file, with their defaults.

Every threshold, sustain time, clearing level, attempt budget, window and dwell comes from the
system file's `recovery:` section (`sdrpeer.system.model.RecoveryDef`, Table III defaults in
`sdrpeer.system.recovery_defaults`). What is here is how the engine treats its inputs: how old a
sample may be and still count, and how long an action is given before its effect is judged. An
agent takes these from the preset its `--preset` names (`sdrpeer.agent.tuning`).
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class RecoveryConfig:
    """How the recovery cores treat samples and actions. Every duration is in seconds."""

    local_stale_after_s: float = 3.0
    """A robot's own agent samples every `metrics_interval` (1 s): a gap longer than this between
    two samples breaks a condition's sustain run (it must hold again for its whole `for:`)."""
    gossip_stale_after_s: float = 12.0
    """Every robot judges the robot-wide conditions of the others from their gossiped records
    and vitals, fed to the monitor at each coordinator step (`DeployConfig.tick`): a gap longer
    than this between two observations of a robot (a stalled loop, a robot out of the view for
    a while) breaks a sustain run."""
    settle_s: float = 10.0
    """After a step taken for a metric condition (memory, CPU), the condition is re-armed and
    samples are ignored for this long (a restart frees and re-reserves memory; a switch needs its
    standby active); if it still holds afterwards, for its `for:` again, the step was unresolved."""

    def __post_init__(self) -> None:
        for name in ("local_stale_after_s", "gossip_stale_after_s", "settle_s"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")


def lan() -> RecoveryConfig:
    """Robots on one Wi-Fi network."""
    return RecoveryConfig()


def lab() -> RecoveryConfig:
    """Many agents on one busy machine: the `lan` values."""
    return RecoveryConfig()


def fast_test() -> RecoveryConfig:
    """Loopback tests and the local lab: a step's effect is judged after 1 s, not 10 s."""
    return RecoveryConfig(settle_s=1.0)
