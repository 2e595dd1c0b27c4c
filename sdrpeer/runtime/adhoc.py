"""Connections made at run time (`sdrpeer port connect`, port taps), beside the plan's.

How it works: `AdHoc` keeps, per connection id, the sending instance and its `ConnectionSpec`.
It never edits the desired set itself: `merged(desired)` returns the desired set with each
sender's ad-hoc connections appended to its spec's own, and that is what the reconciler plans
against (so a new plan, which replaces a spec, keeps them, and the reconciler makes and repairs
them like any other). `prune(desired)` forgets those whose sender left the desired set, or whose
receiver is an instance of this robot (no `to_addr`) that left it: a connection goes when either
end stops. A connection with `to_addr` (a tap, or a receiver on another robot) goes with its
sender or when removed.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace

from sdrpeer.runtime.spec import ConnectionSpec, InstanceSpec


class AdHoc:
    """The run-time connections of one agent, by id."""

    def __init__(self) -> None:
        self._conns: dict[str, tuple[str, ConnectionSpec]] = {}

    def add(self, sender: str, conn: ConnectionSpec) -> None:
        """Add one; ValueError when its id is taken."""
        if conn.id in self._conns:
            raise ValueError(f"connection {conn.id!r} exists already")
        self._conns[conn.id] = (sender, conn)

    def remove(self, conn_id: str) -> bool:
        """Forget one; False when there was none of that id."""
        return self._conns.pop(conn_id, None) is not None

    def items(self) -> list[tuple[str, ConnectionSpec]]:
        """(sender, connection) of each, by id."""
        return [self._conns[cid] for cid in sorted(self._conns)]

    def prune(self, desired: Mapping[str, InstanceSpec]) -> list[str]:
        """Forget connections an end of which is no longer desired; their ids."""
        gone = [
            cid
            for cid, (sender, conn) in self._conns.items()
            if sender not in desired or (conn.to_addr is None and conn.to_instance not in desired)
        ]
        for cid in gone:
            del self._conns[cid]
        return sorted(gone)

    def merged(self, desired: Mapping[str, InstanceSpec]) -> dict[str, InstanceSpec]:
        """`desired` with every sender's ad-hoc connections added to its spec (a plan's own
        connection of the same id wins)."""
        if not self._conns:
            return dict(desired)
        out = dict(desired)
        for sender, conn in self._conns.values():
            spec = out.get(sender)
            if spec is None or any(c.id == conn.id for c in spec.connections):
                continue
            out[sender] = replace(spec, connections=(*spec.connections, conn))
        return out
