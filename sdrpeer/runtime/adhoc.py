"""Connections made at run time (`sdrpeer port connect`, port taps), beside the plan's.

How it works: `AdHoc` keeps, per connection id, the sending instance and its `ConnectionSpec`.
It never edits the desired set itself: `merged(desired)` returns the desired set with each
sender's ad-hoc connections appended to its spec's own, and that is what the reconciler plans
against (so a new plan, which replaces a spec, keeps them, and the reconciler makes and repairs
them like any other). `prune(desired)` forgets those whose sender left the desired set, or whose
receiver is an instance of this robot (no `to_addr`) that left it: a connection goes when either
end stops. A connection with `to_addr` (a tap) goes with its sender or when removed. A *remote*
one (its receiver on another robot) is addressed afresh for each pass by `resolve` (the data
address that robot's record gives now; unknown: `pending`, so one made stays as it is and is
re-pointed when the receiver moves or restarts; moved to this robot: resolved here like a
plan's connection); it goes with its sender or when removed.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import replace

from sdrpeer.runtime.spec import ConnectionSpec, InstanceSpec


class AdHoc:
    """The run-time connections of one agent, by id."""

    def __init__(self) -> None:
        self._conns: dict[str, tuple[str, ConnectionSpec]] = {}
        self._remote: set[str] = set()

    def add(self, sender: str, conn: ConnectionSpec, *, remote: bool = False) -> None:
        """Add one (`remote`: its receiver is on another robot); ValueError when its id is
        taken."""
        if conn.id in self._conns:
            raise ValueError(f"connection {conn.id!r} exists already")
        self._conns[conn.id] = (sender, conn)
        if remote:
            self._remote.add(conn.id)

    def remove(self, conn_id: str) -> bool:
        """Forget one; False when there was none of that id."""
        self._remote.discard(conn_id)
        return self._conns.pop(conn_id, None) is not None

    def items(self) -> list[tuple[str, ConnectionSpec]]:
        """(sender, connection) of each, by id."""
        return [self._conns[cid] for cid in sorted(self._conns)]

    def prune(self, desired: Mapping[str, InstanceSpec]) -> list[str]:
        """Forget connections an end of which is no longer desired; their ids."""

        def receiver_gone(cid: str, conn: ConnectionSpec) -> bool:
            local = cid not in self._remote and conn.to_addr is None
            return local and conn.to_instance not in desired

        gone = [
            cid
            for cid, (sender, conn) in self._conns.items()
            if sender not in desired or receiver_gone(cid, conn)
        ]
        for cid in gone:
            self.remove(cid)
        return sorted(gone)

    def merged(
        self,
        desired: Mapping[str, InstanceSpec],
        resolve: Callable[[str], str | None] = lambda instance: None,
    ) -> dict[str, InstanceSpec]:
        """`desired` with every sender's ad-hoc connections added to its spec (a plan's own
        connection of the same id wins); `resolve`: a remote receiver's data address now."""
        if not self._conns:
            return dict(desired)
        out = dict(desired)
        for cid, (sender, made) in self._conns.items():
            spec = out.get(sender)
            if spec is None or any(c.id == cid for c in spec.connections):
                continue
            conn = made
            if cid in self._remote and made.to_instance in desired:
                conn = replace(made, to_addr=None)  # the receiver moved here: resolved locally
            elif cid in self._remote:
                addr = resolve(made.to_instance)
                conn = replace(made, to_addr=addr, pending=addr is None)
            out[sender] = replace(spec, connections=(*spec.connections, conn))
        return out
