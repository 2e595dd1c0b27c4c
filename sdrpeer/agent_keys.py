"""Key rotation on a running agent: SIGHUP re-reads the key file.

How it works: the key file lists keys, the first signs and all verify. Rotation is three edits of
the file on every robot, each followed by SIGHUP: add the new key second (everyone accepts it),
put it first (everyone signs with it and still accepts the old), remove the old key. On each
reload the gossip codec takes the new keyring, the API accepts the peer token of every key in
it, the agent presents the token of the signing key, and every component host gets the new data
keys (sdrpeer.dataplane.auth). A file that cannot be read changes
nothing (`keys.reload_failed` in the event log). docs/security.md tells the procedure.
"""

from __future__ import annotations

import hashlib
import logging
import time
from typing import TYPE_CHECKING, Final

from sdrpeer.deploy.peers import peer_token, peer_tokens
from sdrpeer.errors import ConfigError
from sdrpeer.keyring import Keyring

if TYPE_CHECKING:
    from sdrpeer.agent import Agent

log = logging.getLogger("sdrpeer.agent")
_DATA_PERSON: Final = b"sdrpeer-data-v1"


def derive_data_key(cluster_key: bytes) -> bytes:
    """The data key of one cluster key (one way: hosts never hold cluster keys)."""
    return hashlib.blake2b(cluster_key[:64], digest_size=32, person=_DATA_PERSON).digest()


def data_keys(ring: Keyring | None) -> tuple[bytes, ...]:
    """The data keys of a keyring, the signing key's first (none without a keyring)."""
    return () if ring is None else tuple(derive_data_key(k) for k in ring.keys)


def reload_keys(agent: Agent) -> bool:
    """Use the keys now in the agent's key file; True when they are in use."""
    key_file = agent.config.key_file
    if agent.keyring is None or key_file is None:
        log.warning("key reload asked, but this agent runs without a key file")
        return False
    try:
        ring = Keyring.from_file(key_file)
    except (ConfigError, OSError, ValueError) as exc:
        log.error("key reload failed, the old keys stay: %s", exc)
        agent.events.add(time.time(), "keys.reload_failed", agent.name, error=str(exc))
        return False
    agent.keyring = ring
    if agent.shell is not None:
        agent.shell.codec.keyring = ring
    agent.peer_tokens[:] = peer_tokens(ring)
    if agent.coordinator is not None:
        agent.coordinator.token = agent.coordinator.handoff.token = peer_token(ring)
    if agent.instances is not None:  # else the stack takes the new ring's keys when it starts
        agent.instances.set_data_keys(data_keys(ring))
    ids = [k.hex() for k in ring.key_ids]
    log.info("keys reloaded: %d key(s), signing with %s", len(ids), ids[0])
    agent.events.add(time.time(), "keys.reloaded", agent.name, key_ids=ids)
    return True
