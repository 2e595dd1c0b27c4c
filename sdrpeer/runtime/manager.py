"""The agent's instance manager: the desired set, one supervisor per instance, the reconcile loop.

How it works: `set_desired` / `remove` change the desired set and wake the loop; `set_desired`
refuses (LaunchRefused, nothing changed) a spec the robot's launch policy does not let run
(`sdrpeer.launch.policy`), so no host starts that the agent's configuration did not allow. The loop
runs on every change (a supervisor's state, a hello, a finished action) and at least every
`interval` seconds: it turns each supervisor into an `Observed`, asks the pure `Reconciler` for
actions at `loop.time()`, and runs each action as its own task (start/stop through the supervisor,
the rest as control commands). When an action finishes the reconciler hears `done`; a failed one
only after `retry_after` seconds, so a refusing host is not hammered. `status()` and `infos()` are
what the API and the gossip record show; `on_change` tells the agent to publish at once. Trouble
goes to the agent's recovery at once, by instance name: `on_fault(name, kind, detail)` for every
fault a component reports, `on_instance_problem(name, cause, detail)` for `component_error` (ERROR)
and `crashed` (the host died unexpectedly); see sdrpeer.runtime.problems; `on_refused(name,
report)` when a receiver refuses one of its outgoing connections (each instance's status shows
the refusal under its connection). `snapshot(name)` and
`restore(name, state)` pass through to the instance's supervisor, and `before_stop(name)`, when set,
runs before an ACTIVE instance is stopped (bounded by `before_stop_timeout`): the agent hands the
instance's last state to its successor there. The instance is deactivated first, so it takes no
frame after that state (the frames it never took are replayed to its successor). Connections made
at run time (`add_connection`: `sdrpeer port connect`, port taps) are kept apart from the desired
set (sdrpeer.runtime.adhoc) and added to it for each reconcile pass, so a new plan keeps them;
they go when either end leaves the desired set.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Awaitable, Callable, Iterable, Mapping
from dataclasses import replace
from pathlib import Path
from typing import Any

from sdrpeer.control.messages import (
    Activate,
    Conn,
    Connect,
    DataKeys,
    Deactivate,
    Disconnect,
    Refused,
    Repoint,
    Reset,
    Step,
)
from sdrpeer.errors import CommandError, LaunchRefused
from sdrpeer.launch.composite import parse_composite
from sdrpeer.launch.policy import LaunchPolicy
from sdrpeer.record.robot import InstanceInfo
from sdrpeer.runtime.adhoc import AdHoc
from sdrpeer.runtime.config import SupervisorConfig
from sdrpeer.runtime.launch import sweep_private_dirs
from sdrpeer.runtime.reconciler import Action, Observed, Reconciler
from sdrpeer.runtime.spec import (
    INSTANCE_ACTIONS,
    ConnectionSpec,
    InstanceSpec,
    connection_to_json,
    desired_to_json,
)
from sdrpeer.runtime.supervisor import Supervisor
from sdrpeer.vocabulary import InstanceState, LifecycleState, ProcessState

log = logging.getLogger(__name__)
ACTIONS = INSTANCE_ACTIONS


def _no_env(spec: InstanceSpec) -> Mapping[str, str]:
    return {}


class InstanceManager:
    """Owns the desired set and the supervisors of one agent."""

    def __init__(
        self,
        data_dir: Path,
        config: SupervisorConfig,
        on_change: Callable[[], None] = lambda: None,
        *,
        interval: float = 0.5,
        retry_after: float = 1.0,
        on_fault: Callable[[str, str, str], None] = lambda name, kind, detail: None,
        on_instance_problem: Callable[[str, str, str], None] = lambda name, cause, detail: None,
        on_refused: Callable[[str, Refused], None] = lambda name, report: None,
        policy: LaunchPolicy | None = None,
    ) -> None:
        self.data_dir = data_dir
        self.policy = policy or LaunchPolicy()
        """What hosts may run here: `set_desired` refuses any other spec."""
        self.config = config
        self.on_change = on_change
        self.on_fault = on_fault
        """Called at once with (instance name, kind, detail) for every fault reported."""
        self.on_instance_problem = on_instance_problem
        self.on_refused = on_refused
        """Called at once with (instance name, report) when a receiver refuses one of its
        outgoing connections (rate-limited by the host), or takes it again (`error` None)."""
        """Called at once with (instance name, cause, detail): component_error or crashed, and
        the supervisor's last error (an exit code, or why it killed the host: "hung: ...")."""
        self.interval = interval
        self.retry_after = retry_after
        self.before_stop: Callable[[str], Awaitable[None]] | None = None
        """Awaited before an ACTIVE instance is stopped (errors are logged, the stop goes on)."""
        self.before_stop_timeout = 2.0
        self.data_keys: tuple[bytes, ...] = ()
        """What new hosts authenticate data connections with (`set_data_keys` on rotation)."""
        self.launch_env: Callable[[InstanceSpec], Mapping[str, str]] = _no_env
        """Variables the agent adds to one host's environment (a `ros2` host's discovery
        settings: sdrpeer.ros2.env), asked when the host is started."""
        self.reconciler = Reconciler(max_starting=config.max_starting)
        self._desired: dict[str, InstanceSpec] = {}
        self._adhoc = AdHoc()
        self.remote_address: Callable[[str], str | None] = lambda instance: None
        """The data address another robot's record gives for an instance (the agent sets it),
        for run-time connections to receivers there."""
        self._sups: dict[str, Supervisor] = {}
        self._wake = asyncio.Event()
        self._loop_task: asyncio.Task[None] | None = None
        self._actions: set[asyncio.Task[None]] = set()

    # ----------------------------------------------------------------- desired set
    def desired(self) -> dict[str, InstanceSpec]:
        """The desired set, by name."""
        return dict(self._desired)

    def set_desired(self, specs: Iterable[InstanceSpec], *, replace_all: bool = False) -> list[str]:
        """Merge specs into the desired set (or replace it); returns the names now desired.
        LaunchRefused (and nothing changes) when the launch policy refuses one of them."""
        specs = list(specs)
        for spec in specs:
            why = self.policy.refusal(spec.launcher, spec.target)
            if why is not None:
                raise LaunchRefused(f"instance {spec.name!r}: {why}")
        new = {} if replace_all else dict(self._desired)
        new.update({s.name: s for s in specs})
        self._desired = new
        self._adhoc.prune(new)
        self.wake()
        return sorted(new)

    def remove(self, name: str) -> bool:
        """Take an instance out of the desired set (it is stopped); False if it was not there.
        Run-time connections from or to it go with it."""
        found = self._desired.pop(name, None) is not None
        self._adhoc.prune(self._desired)
        self.wake()
        return found

    # ----------------------------------------------------------------- run-time connections
    def add_connection(self, sender: str, conn: ConnectionSpec, *, remote: bool = False) -> None:
        """Connect one of `sender`'s OutPorts at run time, beside the plan's connections
        (`remote`: to a receiver on another robot, addressed by `remote_address`; KeyError:
        `sender` is not desired; ValueError: the id is taken, by the plan or another)."""
        spec = self._desired.get(sender)
        if spec is None:
            raise KeyError(sender)
        if any(c.id == conn.id for c in spec.connections):
            raise ValueError(f"connection {conn.id!r} exists already (the plan's)")
        self._adhoc.add(sender, conn, remote=remote)
        self.wake()

    def remove_connection(self, conn_id: str) -> bool:
        """Undo `add_connection`; False when no run-time connection has that id."""
        found = self._adhoc.remove(conn_id)
        self.wake()
        return found

    def adhoc_connections(self) -> list[tuple[str, ConnectionSpec]]:
        """(sender, connection) of every run-time connection."""
        return self._adhoc.items()

    def hello_ports(self, name: str) -> dict[str, list[str]] | None:
        """The ports a running instance's host declared ({"in": [...], "out": [...]}), None
        while it is not running."""
        sup = self._sups.get(name)
        return None if sup is None or sup.hello is None else dict(sup.hello.ports)

    def data_address(self, name: str) -> str | None:
        """Where a sender on this robot reaches the instance's data server, None while it has
        none."""
        sup = self._sups.get(name)
        return None if sup is None else sup.data_address()

    def made_connections(self, name: str) -> dict[str, tuple[ConnectionSpec, str]]:
        """The connections the instance's host has made: id -> (spec, address it sends to)."""
        sup = self._sups.get(name)
        return {} if sup is None else dict(sup.connections)

    async def act(self, name: str, action: str) -> dict[str, Any]:
        """activate/deactivate (changes `desired`), reset and step (the commands), restart (the
        host)."""
        spec = self._desired.get(name)
        if spec is None:
            raise KeyError(name)
        if action in ("activate", "deactivate"):
            new = LifecycleState.ACTIVE if action == "activate" else LifecycleState.INACTIVE
            self._desired[name] = replace(spec, desired=new)
        elif action in ("reset", "step"):
            sup = self._sups.get(name)
            if sup is None:
                raise CommandError(action, "closed", f"{name} is not running")
            await sup.command(Reset() if action == "reset" else Step())
        elif action == "restart":
            sup = self._sups.get(name)
            if sup is not None:
                await sup.restart()
        else:
            raise ValueError(f"unknown action {action!r} (known: {', '.join(ACTIONS)})")
        self.wake()
        return self.status_of(name)

    async def snapshot(self, name: str) -> Any:
        """The state of a running instance (its on_snapshot); CommandError if not running."""
        return await self._running(name, "snapshot").snapshot()

    async def restore(self, name: str, state: Any) -> None:
        """Hand `state` to a running instance's on_restore; CommandError if not running."""
        await self._running(name, "restore").restore(state)

    def _running(self, name: str, what: str) -> Supervisor:
        sup = self._sups.get(name)
        if sup is None or not sup.alive:
            raise CommandError(what, "closed", f"{name} is not running")
        return sup

    # ----------------------------------------------------------------- loop
    def wake(self) -> None:
        """Reconcile soon."""
        self._wake.set()

    async def start(self) -> None:
        """Start the reconcile loop (after removing the host directories dead hosts left)."""
        swept = await asyncio.to_thread(sweep_private_dirs, time.time())
        if swept:
            log.info("removed %d host directories left by hosts no agent stopped", swept)
        self._loop_task = asyncio.create_task(self._loop(), name="instance-manager")

    async def stop(self) -> None:
        """Stop the loop and every host, gracefully and in parallel."""
        if self._loop_task is not None:
            self._loop_task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._loop_task
        for task in list(self._actions):
            task.cancel()
        await asyncio.gather(*self._actions, return_exceptions=True)
        await asyncio.gather(*(s.stop() for s in self._sups.values()), return_exceptions=True)

    def kill_all(self) -> None:
        """SIGKILL every host at once (an agent out of time to stop: no host outlives it)."""
        for sup in self._sups.values():
            sup.kill_now()

    async def _loop(self) -> None:
        while True:
            self._wake.clear()
            try:
                self.reconcile_once()
            except Exception:
                log.exception("reconcile failed")
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(self.interval):
                    await self._wake.wait()

    def reconcile_once(self) -> list[Action]:
        """One reconcile pass: plan and launch the actions."""
        desired = self._adhoc.merged(self._desired, self.remote_address)
        for name, sup in list(self._sups.items()):
            spec = desired.get(name)
            if spec is None and sup.state == ProcessState.STOPPED and not sup.running:
                del self._sups[name]
            elif spec is not None and spec.same_process(sup.spec):
                sup.spec = spec  # lifecycle or links changed: the running host stays
        observed = {name: observe(sup) for name, sup in self._sups.items()}
        now = asyncio.get_running_loop().time()
        actions = self.reconciler.plan(now, desired, observed)
        for action in actions:
            task = asyncio.create_task(self._execute(action))
            self._actions.add(task)
            task.add_done_callback(self._actions.discard)
        return actions

    async def _execute(self, a: Action) -> None:
        ok = False
        try:
            await self._perform(a)
            ok = True
        except CommandError as e:
            log.warning("%s: %s failed: %s", a.instance, a.kind, e)
            sup = self._sups.get(a.instance)
            if sup is not None:
                sup.last_error = f"{a.kind}: {e}"
        except Exception:
            log.exception("%s: %s failed", a.instance, a.kind)
        finally:
            if ok:
                self.reconciler.done(a.instance)
                self.wake()
            else:
                loop = asyncio.get_running_loop()
                loop.call_later(self.retry_after, self._retry, a.instance)

    def _retry(self, name: str) -> None:
        self.reconciler.done(name)
        self.wake()

    async def _perform(self, a: Action) -> None:
        if a.kind == "start":
            spec = self._desired.get(a.instance)
            if spec is None:  # no longer desired since the action was planned
                return
            sup = self._sups.get(a.instance)
            if sup is None:
                sup = Supervisor(
                    spec,
                    self.data_dir,
                    self.config,
                    self._changed,
                    on_fault=lambda s, kind, detail: self.on_fault(s.name, kind, detail),
                    on_problem=lambda s, cause: self.on_instance_problem(
                        s.name, cause, s.last_error or ""
                    ),
                    on_refused=lambda s, report: self.on_refused(s.name, report),
                    data_keys=lambda: self.data_keys,
                    launch_env=self.launch_env,
                )
                self._sups[a.instance] = sup
            sup.spec = spec
            sup.start()
            return
        sup = self._sups[a.instance]
        if a.kind == "stop":
            if self.before_stop is not None and sup.state == LifecycleState.ACTIVE:
                await self._quiesce(sup)  # it takes no more frames: the snapshot is its last
                await self._before_stop(a.instance, self.before_stop)
            await sup.stop()
            if a.instance not in self._desired:
                self._sups.pop(a.instance, None)
            return
        conn = a.conn
        if a.kind == "activate":
            await sup.command(Activate())
        elif a.kind == "deactivate":
            await sup.command(Deactivate())
        elif a.kind == "connect" and conn is not None and a.to is not None:
            wire = Conn(conn.id, conn.out_port, a.to, conn.in_port, conn.policy_map())
            await sup.command(Connect(wire))
            sup.connections[conn.id] = (conn, a.to)
        elif a.kind == "repoint" and conn is not None and a.to is not None:
            await sup.command(Repoint(conn.id, a.to))
            sup.connections[conn.id] = (conn, a.to)
        elif a.kind == "disconnect" and conn is not None:
            sup.connections.pop(conn.id, None)
            await sup.command(Disconnect(conn.id))

    def set_data_keys(self, keys: tuple[bytes, ...]) -> None:
        """New data keys (a key rotation): for hosts started from now on, and sent to every
        running one (`data_keys` command; a host that misses it keeps its old keys)."""
        self.data_keys = keys
        wire = tuple(k.hex() for k in keys)
        for sup in self._sups.values():
            if sup.running:
                task = asyncio.get_running_loop().create_task(self._give_keys(sup, wire))
                self._actions.add(task)
                task.add_done_callback(self._actions.discard)

    @staticmethod
    async def _give_keys(sup: Supervisor, wire: tuple[str, ...]) -> None:
        try:
            await sup.command(DataKeys(wire))
        except CommandError as e:
            log.warning("%s: data keys not updated: %s", sup.name, e)

    async def _quiesce(self, sup: Supervisor) -> None:
        """Deactivate an instance about to stop, so that the state it hands over is the last
        and the frames it never took stay unacknowledged (its senders replay them to the next
        instance: docs/protocol.md, acknowledgements)."""
        try:
            async with asyncio.timeout(self.before_stop_timeout):
                await sup.command(Deactivate())
        except (CommandError, TimeoutError) as e:
            log.info("%s: deactivate before stop failed (%s); stopping anyway", sup.name, e)

    async def _before_stop(self, name: str, hook: Callable[[str], Awaitable[None]]) -> None:
        try:
            async with asyncio.timeout(self.before_stop_timeout):
                await hook(name)
        except TimeoutError:
            log.warning(
                "%s: before_stop took over %gs; stopping anyway", name, self.before_stop_timeout
            )
        except Exception:  # the stop must happen whatever the hook does
            log.warning("%s: before_stop failed; stopping anyway", name, exc_info=True)

    def _changed(self, sup: Supervisor) -> None:
        self.wake()
        self.on_change()

    # ----------------------------------------------------------------- views
    def sample(self) -> None:
        """Measure every host's CPU % and RSS (call once per metrics tick)."""
        for sup in self._sups.values():
            sup.sample()

    def log_file(self, name: str) -> Path | None:
        """The log file of an instance this agent knows, else None."""
        sup = self._sups.get(name)
        if sup is not None:
            return sup.log_file()
        return self.data_dir / "instances" / f"{name}.log" if name in self._desired else None

    def status_of(self, name: str) -> dict[str, Any]:
        """One instance's status dict (see `status`)."""
        spec = self._desired.get(name)
        sup = self._sups.get(name)
        if sup is None:
            assert spec is not None
            sup = Supervisor(spec, self.data_dir, self.config)
        return status_dict(sup, spec)

    def status(self) -> list[dict[str, Any]]:
        """Every desired or running instance, sorted by name."""
        return [self.status_of(n) for n in sorted(set(self._desired) | set(self._sups))]

    def port_counters(self) -> dict[str, dict[str, dict[str, int]]]:
        """Instance -> port -> counters, from each running host's last heartbeat."""
        return {name: sup.ports for name, sup in self._sups.items() if sup.ports}

    def endpoints(self) -> dict[str, dict[str, list[str]]]:
        """Instance -> its ROS 2 node's topics and services (name -> [direction, ROS type]),
        from each running ROS 2 host's last heartbeat."""
        return {name: sup.endpoints for name, sup in self._sups.items() if sup.endpoints}

    def port_rates(self) -> dict[str, dict[str, dict[str, float]]]:
        """Instance -> port -> frames and bytes per second between its last two heartbeats."""
        return {name: sup.port_rates for name, sup in self._sups.items() if sup.port_rates}

    def infos(self) -> tuple[InstanceInfo, ...]:
        """What the robot's gossip record says about its instances."""
        return tuple(
            InstanceInfo(
                name=sup.name,
                component=sup.spec.component,
                state=_record_state(sup, self._desired.get(sup.name)),
                role=sup.spec.role,
                cpu_pct=round(sup.cpu_pct, 1),
                rss=sup.rss,
                data=sup.tcp_address(),
                out_bps=round(sup.out_bps),
                out_lost=math.ceil(sup.out_lost_ps),  # one frame lost in a while still shows
                out_refused=sum(1 for c in sup.refusals if c in sup.connections),
            )
            for _, sup in sorted(self._sups.items())
        )


def _record_state(sup: Supervisor, desired: InstanceSpec | None) -> InstanceState:
    """The state gossip shows: UPDATING while the running host has an outdated spec."""
    if desired is not None and not desired.same_process(sup.spec):
        return ProcessState.UPDATING
    return sup.state


def observe(sup: Supervisor) -> Observed:
    """What the reconciler needs to know of one supervisor."""
    return Observed(sup.state, sup.spec, sup.data_address(), dict(sup.connections))


def status_dict(sup: Supervisor, spec: InstanceSpec | None) -> dict[str, Any]:
    """The JSON status of one instance (GET /v1/instances)."""
    desired = desired_to_json(spec.desired) if spec is not None else "removed"
    conns = []
    for cid, (conn, addr) in sorted(sup.connections.items()):
        refused = sup.refusals.get(cid)  # None: not refused by its receiver now
        conns.append({**connection_to_json(conn), "id": cid, "addr": addr, "refused": refused})
    return {
        "name": sup.name,
        "component": sup.spec.component,
        "state": sup.state,
        "desired": desired,
        "role": sup.spec.role,
        "pid": sup.pid,
        "cpu_pct": round(sup.cpu_pct, 1),
        "rss": sup.rss,
        "out_bps": round(sup.out_bps),
        "restarts": sup.restarts,
        "since": round(sup.since, 3),
        "connections": conns,
        "data": {} if sup.hello is None else dict(sup.hello.data),
        "services": {} if sup.hello is None else dict(sup.hello.services or {}),
        "last_error": sup.last_error,
        "ports": sup.ports,
        "data_plane": sup.data_plane,
        "start_latency_s": None if sup.start_latency is None else round(sup.start_latency, 4),
        "protocol_errors": sup.protocol_errors,
        "faults": [f.to_json() for f in sup.faults],
        "log": str(sup.log_file()),
        **composite_members(sup.spec, sup.state, sup.last_error),
    }


def composite_members(
    spec: InstanceSpec, state: InstanceState, error: str | None
) -> dict[str, Any]:
    """A composite's `members` for its status (name, target, state: they share the
    composite's; `failed`: the member an ERROR's text names); nothing for another instance."""
    if spec.launcher != "composite" or not isinstance(spec.target, str):
        return {}
    try:
        members = parse_composite(spec.target).members
    except ValueError:
        return {}
    rows = []
    for name, target in members:
        failed = state == LifecycleState.ERROR and f"member {name}: " in (error or "")
        rows.append({"name": name, "target": target, "state": state, "failed": failed})
    return {"members": rows}
