"""Key commands for a running fleet (`sdrpeer key list|add|primary|retire`): the agent the
operator asks applies a keyring change on every robot, as Serf's `serf keys` does.

How it works: the operator's request (with its token) reaches one agent; `fleet_change` checks
the change against every reachable robot first, then posts it to each alive robot's API with the
peer token (HTTP between agents, authenticated with the current cluster key), applies it here,
and answers robot by robot. A new key travels sealed under the current key, bound to its
receiver (sdrpeer.keys.transport); key ids and the order of the ring are all that travel in
clear. The steps of a rotation keep every datagram opening everywhere, so no robot is ever
suspected for its keys:
- `add KEY`: every robot opens with KEY too (it does not seal with it yet);
- `primary ID`: every robot seals with key ID; refused unless every robot holds it;
- `retire ID`: every robot forgets key ID; refused while any robot seals with it.
An alive robot that does not answer fails the change (`ok` false; `primary` and `retire` are
refused up front while one does not answer). A robot that is not alive (dead, not yet reaped)
cannot be asked: the answer names it, and it needs the new key file by hand when it comes back
after the old key was retired (docs/deploy.md). Each agent saves the ring it uses
(sdrpeer.keys.store), so restarts keep it. Each request to a robot is tried `ATTEMPTS` times.
"""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Final

from sdrpeer.errors import ApiError, ConfigError
from sdrpeer.keys.keyring import Keyring, key_id, parse_key_id
from sdrpeer.keys.transport import open_key, seal_key

__all__ = ["OPS", "KeyAdmin", "KeyChangeRefused", "apply_change", "ring_json"]

OPS: Final = ("add", "primary", "retire")
ATTEMPTS: Final = 3
RETRY_PAUSE: Final = 0.3
"""Seconds between two attempts at one robot."""


class KeyChangeRefused(ConfigError):
    """A key change that would lock a robot out, refused before anything changed."""


def ring_json(name: str, ring: Keyring) -> dict[str, Any]:
    """What a robot says of its ring: ids only, the primary (sealing) key's first."""
    ids = [k.hex() for k in ring.key_ids]
    return {"name": name, "primary": ids[0], "keys": ids}


def apply_change(ring: Keyring, op: str, key: bytes | None, kid: bytes | None) -> Keyring:
    """The ring after one change (`key` for add, `kid` for primary and retire)."""
    if op == "add" and key is not None:
        return ring.with_key(key)
    if op == "primary" and kid is not None:
        return ring.with_primary(kid)
    if op == "retire" and kid is not None:
        return ring.without(kid)
    raise ConfigError(f"unknown key operation {op!r} (known: {', '.join(OPS)})")


def parse_change(
    body: dict[str, Any], ring: Keyring, me: str
) -> tuple[str, bytes | None, bytes | None]:
    """(op, key, kid) of a robot-to-robot change body; ConfigError naming the bad field."""
    op = body.get("op")
    if op not in OPS:
        raise ConfigError(f'field "op": expected one of {", ".join(OPS)}, got {op!r}')
    if op == "add":
        return op, open_key(ring, body.get("key"), me), None
    try:
        return op, None, parse_key_id(str(body.get("key_id", "")))
    except ValueError as exc:
        raise ConfigError(f'field "key_id": {exc}') from None


@dataclass(slots=True)
class KeyAdmin:
    """The fleet side of the key commands, for one agent."""

    name: str
    ring: Callable[[], Keyring | None]
    """The ring in use (None: the agent runs without a key)."""
    use: Callable[[Keyring, str], None]
    """Put a ring in use here (and save it), saying why."""
    peers: Callable[[], tuple[dict[str, str | None], list[str]]]
    """(alive other robots -> their API address, members that are not alive)."""
    call: Callable[..., Any]
    """`sdrpeer.api.peer_client.call` (api, method, path, token, body=...)."""
    token: Callable[[], str]
    """The peer token to present (that of the sealing key)."""
    _busy: asyncio.Lock = field(default_factory=asyncio.Lock)
    """One fleet change at a time through this agent."""

    def current(self) -> Keyring:
        """The ring in use; KeyChangeRefused when the agent has none."""
        ring = self.ring()
        if ring is None:
            raise KeyChangeRefused("this agent runs without a cluster key (--insecure)")
        return ring

    def change_here(self, body: dict[str, Any]) -> dict[str, Any]:
        """Apply a change another agent posted (POST /v1/keys); this robot's ring after it."""
        ring = self.current()
        op, key, kid = parse_change(body, ring, self.name)
        new = apply_change(ring, op, key, kid)
        if new.keys != ring.keys:
            self.use(new, f"key {op}")
        return ring_json(self.name, new)

    async def fleet_list(self) -> dict[str, Any]:
        """Every alive robot's ring (or why it did not answer), and who was not alive."""
        apis, missed = self.peers()
        robots: dict[str, Any] = {self.name: ring_json(self.name, self.current())}
        answers = await asyncio.gather(
            *(self._ask(api, "GET", "/v1/keys", None) for api in apis.values())
        )
        robots.update(zip(apis, answers, strict=True))
        return {"robots": dict(sorted(robots.items())), "not_alive": missed}

    async def fleet_change(self, op: str, key: bytes | None, kid: bytes | None) -> dict[str, Any]:
        """Check, then apply a change on every alive robot; the answer robot by robot, `ok`
        when every one took it. KeyChangeRefused when a check fails (nothing changed)."""
        ring = self.current()
        if op not in OPS:
            raise ConfigError(f'field "op": expected one of {", ".join(OPS)}, got {op!r}')
        apply_change(ring, op, key, kid)  # refused here first (retire the primary, ...)
        if op != "add":
            assert kid is not None
            self._check(await self.fleet_list(), op, kid)
        apis, missed = self.peers()
        bodies = {name: self._body(ring, op, key, kid, name) for name in apis}
        answers = await asyncio.gather(
            *(self._ask(api, "POST", "/v1/keys", bodies[name]) for name, api in apis.items())
        )
        robots: dict[str, Any] = dict(zip(apis, answers, strict=True))
        here = self.current()  # a SIGHUP may have changed it meanwhile
        new = apply_change(here, op, key, kid)
        if new.keys != here.keys:
            self.use(new, f"key {op}")
        robots[self.name] = ring_json(self.name, new)
        ok = all("error" not in doc for doc in robots.values())
        changed = key_id(key).hex() if key is not None else (kid or b"").hex()
        return {
            "op": op,
            "key_id": changed,
            "ok": ok,
            "robots": dict(sorted(robots.items())),
            "not_alive": missed,
        }

    @staticmethod
    def _check(listing: dict[str, Any], op: str, kid: bytes) -> None:
        wanted = kid.hex()
        problems = []
        for robot, doc in listing["robots"].items():
            if "error" in doc:
                problems.append(f"{robot} did not answer ({doc['error']})")
            elif op == "primary" and wanted not in doc["keys"]:
                problems.append(f"{robot} does not hold key {wanted} (sdrpeer key add it first)")
            elif op == "retire" and doc["primary"] == wanted:
                problems.append(f"{robot} seals with key {wanted} (make another key primary)")
        if problems:
            raise KeyChangeRefused(
                f"key {op} {wanted} refused, nothing changed: " + "; ".join(problems)
            )

    @staticmethod
    def _body(
        ring: Keyring, op: str, key: bytes | None, kid: bytes | None, robot: str
    ) -> dict[str, Any]:
        if op == "add":
            assert key is not None
            return {"op": op, "key": seal_key(ring, key, robot)}
        assert kid is not None
        return {"op": op, "key_id": kid.hex()}

    async def _ask(self, api: str | None, method: str, path: str, body: Any) -> dict[str, Any]:
        """One robot's answer, tried ATTEMPTS times; {"error": ...} when none worked."""
        if not api:
            return {"error": "publishes no API address"}
        error = ""
        for attempt in range(ATTEMPTS):
            if attempt:
                await asyncio.sleep(RETRY_PAUSE)
            try:
                status, doc = await self.call(api, method, path, self.token(), body=body)
            except ApiError as exc:
                error = str(exc)
                continue
            if status == 200 and isinstance(doc, dict):
                return doc
            error = f"answered {status}: {doc.get('error') if isinstance(doc, dict) else doc}"
            if 400 <= status < 500:
                break  # refused: asking again changes nothing
        return {"error": error}
