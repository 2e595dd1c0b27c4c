"""One hosted component instance: its runner, its runtime ports, its outgoing connections.

How it works: `HostedInstance` turns control commands (the dataclasses of sdrpeer.control.messages,
their fields' types already checked by the codec) into calls on the SDK's `ComponentRunner`
(lifecycle, parameters) and on the data plane (`Connection` objects attached to our OutPorts). It
reports every lifecycle change and fault through the `report` callback the moment the runner
announces it, so an exception in `on_execute` becomes a `state ERROR` report without waiting for a
heartbeat (an ERROR a fault caused says the fault's kind). `snapshot` and `restore` are
sdrpeer.host.handoff's; `execute` returns the bytes a command sends back in `part`s (snapshot), else
None. A connection to the host's own data address is a `LocalLink` (sdrpeer.host.local_link: a
composite's members feeding each other in process). It raises `CommandRefused` (our peer's
mistake: a bad value, an unknown port or connection) or whatever the runner raised (an illegal
transition, a failing callback); the caller turns either into `reply ok=false`. The data
server's `resolve` is `in_port`, its `resolve_service` `service`. A `connect` whose `out` is one
of our consumer service ports makes a service binding (sdrpeer.dataplane.service's
`ServiceClient`, bound to the port's `ServiceCaller`) instead of a data stream; `disconnect` and
`repoint` treat both alike. Provided services answer only while the component is ACTIVE. A
receiver refusing one of our data streams or service bindings is logged and reported to the
agent (`refused`: the first refusal at once, then at most once per 30 s per connection,
sdrpeer.dataplane.refusals; and once more, with no error, when it gets through again).
`release_senders` (the host is exiting) lets a component blocked in `send()` go, so finalizing
never waits on a receiver; `deactivate` does the same for the connections refused now.
"""

from __future__ import annotations

import asyncio
import inspect
import logging
import time
from collections.abc import Callable
from typing import Any

from sdrpeer.control.host_side import Request
from sdrpeer.control.messages import (
    Activate,
    Conn,
    Connect,
    DataKeys,
    Deactivate,
    Disconnect,
    Exit,
    Fault,
    Refused,
    Repoint,
    Report,
    Reset,
    Restore,
    SetParams,
    Snapshot,
    State,
    Step,
)
from sdrpeer.dataplane import Connection
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.dataplane.refusals import RefusalWatch
from sdrpeer.dataplane.service import ServiceClient
from sdrpeer.errors import CommandRefused, SdrpeerError
from sdrpeer.host import handoff
from sdrpeer.host.local_link import LocalLink
from sdrpeer.sdk import (
    Component,
    ComponentRunner,
    ConnectorPolicy,
    InPortRuntime,
    OutPortRuntime,
    ServiceCaller,
    ServiceProviderRuntime,
)
from sdrpeer.vocabulary import LifecycleState

log = logging.getLogger("sdrpeer.host")

ReportTo = Callable[[Report], None]


async def maybe_await(value: object) -> None:
    """Await `value` if the API we called turned out to be async."""
    if inspect.isawaitable(value):
        await value


def _state_name(value: object) -> str:
    """`ACTIVE` from an enum member or a string."""
    name = getattr(value, "name", None)
    return name if isinstance(name, str) else str(value)


class HostedInstance:
    """A component instance as the host drives it."""

    def __init__(
        self,
        name: str,
        component: Component,
        runner: ComponentRunner,
        report: ReportTo,
        *,
        clock: Callable[[], float] = time.time,
        auth: DataAuth | None = None,
    ) -> None:
        self.name = name
        self.auth = auth if auth is not None else DataAuth(())
        """The data keys of this host's connections, both ways (sdrpeer.dataplane.auth)."""
        self.on_taking: Callable[[bool], None] | None = None
        """Told whether the component takes frames now (ACTIVE): the data server's
        `set_taking`, so a sender that left hears at once what an inactive one never took."""
        self.component = component
        self.runner = runner
        self.report = report
        self.clock = clock
        names = type(component).port_names()
        self.in_ports = {n: component.inport(n) for n in names["in"]}
        self.out_ports = {n: component.outport(n) for n in names["out"]}
        self.connections: dict[str, tuple[Connection | LocalLink, OutPortRuntime]] = {}
        self.own_addresses: frozenset[str] = frozenset()
        """This host's data addresses (`tcp://...`, `unix://...`): a connection to one of them
        is a `LocalLink` (set by the host once its data server listens)."""
        services = type(component).service_ports()
        self.providers = {
            n: component.provider(n) for n, i in services.items() if i.role == "provides"
        }
        self.consumers = {
            n: component.consumer(n) for n, i in services.items() if i.role == "requires"
        }
        self.bindings: dict[str, tuple[ServiceClient, ServiceCaller]] = {}
        """Service bindings from our consumer ports, by connection id."""
        self.refusals = RefusalWatch()
        """Which refusals of our outgoing data streams to report (rate-limited)."""
        self.state = _state_name(runner.state)
        self._serve(self.state)

    def watch(self) -> None:
        """Start reporting state changes and faults (after `hello` went out)."""
        self.runner.on_state(self._on_state)
        self.runner.on_fault(self._on_fault)

    def _on_state(self, state: object, error: object) -> None:
        """The runner changed state: report it now."""
        name = _state_name(state)
        if name == self.state and error is None:
            return
        self.state = name
        self._serve(name)
        if self.on_taking is not None:
            self.on_taking(name == LifecycleState.ACTIVE)
        text = None if error is None else (str(error) or type(error).__name__)
        log.info("state %s%s", name, f" ({text})" if text else "")
        fault = self.runner.fault if name == LifecycleState.ERROR else None
        self.report(State(name, self.clock(), text, fault))

    def _serve(self, state: str) -> None:
        """Provided services answer calls only while ACTIVE."""
        for provider in self.providers.values():
            provider.serving = state == LifecycleState.ACTIVE
            provider.state = state

    def _on_fault(self, kind: str, detail: str) -> None:
        """The component reported a fault: pass it on."""
        self.report(Fault(str(kind), str(detail), self.clock()))

    def ports(self) -> dict[str, list[str]]:
        """Port names by direction, for `hello`."""
        return type(self.component).port_names()

    def services(self) -> dict[str, dict[str, Any]]:
        """Service ports by name (role, interface id, methods), for `hello`."""
        return {n: i.to_map() for n, i in type(self.component).service_ports().items()}

    def service(self, name: str) -> ServiceProviderRuntime | None:
        """The provided service port called `name` (the data server's `resolve_service`)."""
        return self.providers.get(name)

    def params(self) -> dict[str, Any]:
        """Current parameter values, for `hello`."""
        return self.component.param_values()

    def in_port(self, name: str) -> InPortRuntime | None:
        """The runtime InPort called `name` (the data server's `resolve`)."""
        return self.in_ports.get(name)

    def counters(self) -> dict[str, dict[str, int]]:
        """Per-port counters, for heartbeats."""
        return self.component.port_counters()

    async def execute(self, request: Request) -> bytes | None:
        """Carry out a command; the bytes it sends back, or None (raises if it failed)."""
        match request.command:
            case Activate():
                await maybe_await(self.runner.activate())
            case Deactivate():
                refused = self._release_refused()
                try:
                    await maybe_await(self.runner.deactivate())
                finally:
                    for connection in refused:
                        connection.hold()
            case Reset():
                await maybe_await(self.runner.reset())
            case SetParams(params=params):
                await maybe_await(self.runner.set_params(params))
            case Connect(conn=conn):
                await self._connect(conn)
            case Disconnect(conn_id=conn_id):
                await self._disconnect(conn_id)
            case Repoint(conn_id=conn_id, to=to):
                self._repoint(conn_id, to)
            case DataKeys(keys=keys):
                self._data_keys(keys)
            case Snapshot() as snapshot:
                return await handoff.snapshot(self.runner, snapshot)
            case Restore():
                await handoff.restore(self.runner, request.blob or b"")
            case Step(n=n):
                if n < 1:
                    raise CommandRefused("'n': expected an integer >= 1")
                await self.runner.step(n)
            case Exit():
                raise CommandRefused("exit is the host's to carry out")
        return None

    async def _connect(self, conn: Conn) -> None:
        """Open a data stream from one of our OutPorts."""
        conn_id, out, to, in_port = conn.id, conn.out_port, conn.to, conn.in_port
        policy_map = conn.policy or {}
        if conn_id in self.connections or conn_id in self.bindings:
            raise CommandRefused(f"connection {conn_id!r} already exists")
        if out in self.consumers:
            self._bind(conn)
            return
        port = self.out_ports.get(out)
        if port is None:
            raise CommandRefused(f"no OutPort {out!r} (have: {', '.join(sorted(self.out_ports))})")
        try:
            policy = ConnectorPolicy.from_map(policy_map)
        except (ValueError, TypeError, SdrpeerError) as exc:
            raise CommandRefused(f"conn 'policy': {exc}") from None
        local = self.in_ports.get(in_port) if to in self.own_addresses else None
        if local is not None:
            if port.type_id is not None and local.type_id not in (None, port.type_id):
                raise CommandRefused(
                    f"conn 'in': {in_port} takes {local.type_id}, {out} sends {port.type_id}"
                )
            link = LocalLink(conn_id, local, dict(policy_map))
            port.attach(link)
            self.connections[conn_id] = (link, port)
            log.info("connection %s: %s.%s -> %s (in process)", conn_id, self.name, out, in_port)
            return
        try:
            connection = Connection(
                conn_id,
                to,
                in_port,
                f"{self.name}.{out}",
                policy,
                auth=self.auth,
                given=policy_map,
                type_id=port.type_id,
            )
        except ValueError as exc:
            raise CommandRefused(f"conn 'to': {exc}") from None
        connection.refusals.on_refused = lambda reason: self._refused(
            conn_id, f"{self.name}.{out}", to, in_port, reason
        )
        connection.start()
        port.attach(connection)
        self.connections[conn_id] = (connection, port)
        log.info("connection %s: %s.%s -> %s %s", conn_id, self.name, out, to, in_port)

    def _refused(self, conn_id: str, from_: str, to: str, in_port: str, reason: str | None) -> None:
        """A receiver refused our connection or binding `conn_id` (None: it got through again):
        log and report it to the agent when `refusals` says it is due."""
        now = self.clock()
        if reason is None:
            told = self.refusals.accepted(conn_id)
        else:
            told = self.refusals.refused(now, conn_id, reason)
        if told is None:
            return
        where = f"{from_} -> {to} {in_port}"
        if told.error is None:
            log.info("connection %s (%s): accepted again", conn_id, where)
        else:
            log.warning(
                "connection %s (%s): refused by the receiver (%d time(s) since last said): %s",
                conn_id,
                where,
                told.count,
                told.error,
            )
        self.report(Refused(conn_id, from_, to, in_port, told.error, told.count, now))

    def _release_refused(self) -> list[Connection]:
        """Let a component blocked in `send()` on a connection its receiver refuses go (so that
        `deactivate` gets the component's lock); the connections released. A connection that
        is only down (reconnecting) keeps its writers waiting: a planned move loses nothing."""
        refused = [
            c
            for c, _ in self.connections.values()
            if isinstance(c, Connection) and c.refusals.last is not None
        ]
        for connection in refused:
            connection.release()
        return refused

    def release_senders(self) -> None:
        """The host is exiting: no component waits in `send()` for a connection any more."""
        for connection, _ in self.connections.values():
            if isinstance(connection, Connection):
                connection.release()

    def _bind(self, conn: Conn) -> None:
        """Bind one of our consumer ports to a provider (a service binding)."""
        caller = self.consumers[conn.out_port]
        if any(c is caller for _, c in self.bindings.values()):
            raise CommandRefused(f"service port {conn.out_port!r} is bound already")
        encrypt = (conn.policy or {}).get("encrypt", True)
        if not isinstance(encrypt, bool):
            raise CommandRefused("conn 'policy': 'encrypt' must be true or false")
        try:
            client = ServiceClient(
                conn.id,
                conn.to,
                conn.in_port,
                f"{self.name}.{conn.out_port}",
                caller.interface.id,
                auth=self.auth,
                encrypt=encrypt,
            )
        except ValueError as exc:
            raise CommandRefused(f"conn 'to': {exc}") from None
        client.refusals.on_refused = lambda reason: self._refused(
            conn.id, client.hello.from_, client.to, conn.in_port, reason
        )
        caller.bind(client)
        self.bindings[conn.id] = (client, caller)
        log.info(
            "service binding %s: %s.%s -> %s %s",
            conn.id,
            self.name,
            conn.out_port,
            conn.to,
            conn.in_port,
        )

    def _lookup(self, conn_id: str) -> tuple[Connection | LocalLink, OutPortRuntime]:
        """The connection a command names."""
        if conn_id not in self.connections:
            raise CommandRefused(f"no connection {conn_id!r}")
        return self.connections[conn_id]

    async def _disconnect(self, conn_id: str) -> None:
        """Close a data stream (or a service binding)."""
        self.refusals.forget(conn_id)
        if conn_id in self.bindings:
            client, caller = self.bindings.pop(conn_id)
            caller.bind(None)
            await client.close()
            log.info("service binding %s closed", conn_id)
            return
        connection, port = self._lookup(conn_id)
        del self.connections[conn_id]
        port.detach(connection)
        await maybe_await(connection.close())
        log.info("connection %s closed", conn_id)

    def _repoint(self, conn_id: str, to: str) -> None:
        """Send the next frames of a connection (or calls of a binding) to a new address."""
        if conn_id in self.bindings:
            try:
                self.bindings[conn_id][0].repoint(to)
            except ValueError as exc:
                raise CommandRefused(f"'to': {exc}") from None
            log.info("service binding %s repointed to %s", conn_id, to)
            return
        connection, _port = self._lookup(conn_id)
        if isinstance(connection, LocalLink):
            raise CommandRefused(f"connection {conn_id!r} is in process: it has no address")
        try:
            connection.repoint(to)
        except ValueError as exc:
            raise CommandRefused(f"'to': {exc}") from None
        log.info("connection %s repointed to %s", conn_id, to)

    def _data_keys(self, keys: tuple[str, ...]) -> None:
        """New data keys (the agent's keys rotated): every later handshake uses them."""
        try:
            parsed = [bytes.fromhex(k) for k in keys]
        except ValueError:
            raise CommandRefused("'keys': expected hex strings") from None
        if not all(16 <= len(k) <= 64 for k in parsed):
            raise CommandRefused("'keys': expected hex strings of 16 to 64 bytes")
        if not parsed and self.auth.enabled:
            raise CommandRefused("'keys': a host with data keys cannot be left without any")
        self.auth.keys[:] = parsed
        log.info("data keys updated: %d key(s)", len(parsed))

    async def close_connections(self) -> None:
        """Detach and close every outgoing connection (all at once: each may linger)."""

        async def close(conn_id: str, connection: Connection | LocalLink) -> None:
            try:
                await maybe_await(connection.close())
            except Exception:
                log.exception("closing connection %s", conn_id)

        closing = []
        for conn_id, (client, caller) in list(self.bindings.items()):
            del self.bindings[conn_id]
            caller.bind(None)
            closing.append(client.close())
        for provider in self.providers.values():
            provider.cancel()
        for conn_id, (connection, port) in list(self.connections.items()):
            del self.connections[conn_id]
            port.detach(connection)
            closing.append(close(conn_id, connection))
        await asyncio.gather(*closing)
