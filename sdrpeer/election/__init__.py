"""The allocator election: a bully election over the gossip view, with epochs and fencing.

How it works: `Election` (core.py) is a pure core fed with one `Candidate` per robot; it says
which robot is the allocator and what this robot publishes (`ElectionState`, encoded by
`state.py`). `Fence` (fence.py) refuses plans and commands from older epochs. `health.py` turns
metrics into eligibility and a coarse health bucket; `rules.py` holds the role table.
"""

from sdrpeer.election.config import ElectionConfig, fast_test, lan
from sdrpeer.election.core import Election
from sdrpeer.election.events import Elected, ElectionEvent, LeaderChanged, SteppedDown
from sdrpeer.election.fence import Fence
from sdrpeer.election.health import eligible, health_bucket
from sdrpeer.election.rules import Role
from sdrpeer.election.state import (
    NO_STATE,
    Candidate,
    ElectionState,
    decode_state,
    encode_state,
    rank,
    state_from_wire,
    state_to_wire,
)
from sdrpeer.errors import ElectionError

__all__ = [
    "NO_STATE",
    "Candidate",
    "Elected",
    "Election",
    "ElectionConfig",
    "ElectionError",
    "ElectionEvent",
    "ElectionState",
    "Fence",
    "LeaderChanged",
    "Role",
    "SteppedDown",
    "decode_state",
    "eligible",
    "encode_state",
    "fast_test",
    "health_bucket",
    "lan",
    "rank",
    "state_from_wire",
    "state_to_wire",
]
