"""The agent: one per robot. Wires gossip, monitoring and the HTTP API together.

How it works: the agent binds its UDP gossip socket and its HTTP API (either may be port 0), writes
`DATA_DIR/agent.json` so a lab or a person can find them, joins through the seeds, and then once per
metrics interval samples the robot (real hardware, or a virtual robot driven by a robot file and a
scenario), raises traps on threshold crossings at once, and builds its record (metrics, link
summary, API address, priority, instances, election, plan). The `Publisher`
(sdrpeer.monitor.publish) decides whether the sample makes a new record (spread to every robot), a
vitals revision (carried on our probes) or nothing. Everything the API shows comes from the gossip
core's view plus the records decoded here, each with its newest vitals laid over it (the views
of AgentView are methods here: they read the agent's own state). `reload_keys` (SIGHUP) and the
key commands (`keys`, sdrpeer.agent.keyadmin) hand a new keyring to every part that holds a key
(`use_keyring`), which saves it in the data directory (sdrpeer.keys.store). With `discover`
the agent also joins what mDNS finds (`discovery`, sdrpeer.agent.discovery). SIGINT/SIGTERM:
graceful leave; a second signal: immediate exit.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import random
import time
from collections import Counter
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from sdrpeer import __version__
from sdrpeer.agent import files as agent_files
from sdrpeer.agent.files import load_token, write_agent_json
from sdrpeer.agent.keyadmin import KeyAdmin
from sdrpeer.agent.keyroutes import ROUTES as KEY_ROUTES
from sdrpeer.agent.tuning import Tuning, preset
from sdrpeer.api import peer_client
from sdrpeer.api.connections import COUNTERS
from sdrpeer.api.server import GuardedSite, serve_api
from sdrpeer.config import AgentConfig, parse_hostport
from sdrpeer.dashboard.feed import Feed
from sdrpeer.dashboard.routes import ROUTES as DASHBOARD_ROUTES
from sdrpeer.deploy.routes import ROUTES as DEPLOY_ROUTES
from sdrpeer.deploy.view import ClusterState
from sdrpeer.errors import ConfigError, RecordError
from sdrpeer.eventlog import EventKind, EventLog, RecoveryTally
from sdrpeer.gossip.core import Membership
from sdrpeer.gossip.events import (
    REAPED,
    CoreEvent,
    EventReceived,
    MemberChanged,
    ProbeOutcome,
    RecordChanged,
    VitalsChanged,
)
from sdrpeer.gossip.udp_shell import GossipShell, open_gossip
from sdrpeer.gossip.wire import REASONS, Codec, Keyring
from sdrpeer.keys.derive import data_keys, peer_token, peer_tokens
from sdrpeer.keys.store import load_ring, save_ring
from sdrpeer.launch.launchers import offered
from sdrpeer.monitor.links import LinkTable, distance
from sdrpeer.monitor.procstats import ProcessTreeMeter, trim_heap
from sdrpeer.monitor.publish import (
    RECORD,
    Average,
    Publisher,
    boundaries,
    link_bounds,
    publish,
)
from sdrpeer.monitor.sources import HostMetrics
from sdrpeer.monitor.traps import TrapDetector, decode_trap, encode_trap
from sdrpeer.ports.routes import ROUTES as PORT_ROUTES
from sdrpeer.record.robot import (
    InstanceInfo,
    LinkBounds,
    Metrics,
    RobotRecord,
    Vitals,
    apply_vitals,
    decode_record,
    decode_vitals,
    link_to_json,
    metrics_to_json,
    record_to_json,
    state_to_wire,
)
from sdrpeer.runtime.overflow import OverflowWatch
from sdrpeer.vocabulary import LifecycleState, MemberState

if TYPE_CHECKING:
    from aiohttp.web import AppRunner

    from sdrpeer.agent.discovery import Discovery
    from sdrpeer.control.messages import Refused
    from sdrpeer.deploy.coordinator import Coordinator
    from sdrpeer.monitor.scenario import Scenario
    from sdrpeer.monitor.virtual import VirtualRobot
    from sdrpeer.runtime.manager import InstanceManager
    from sdrpeer.runtime.spec import InstanceSpec

log = logging.getLogger("sdrpeer.agent")

METER_MAX_AGE = 0.25
"""Seconds a measurement of this robot's processes (cpu, memory) is reused
(`ProcessTreeMeter.max_age`): the metrics loop samples once a second, every instance change
samples again at once."""

INSECURE_WARNING = (
    "running INSECURE (no cluster key): gossip on %s is neither authenticated, encrypted nor "
    "replay-protected: anyone who can reach it reads every robot's metrics, position and plan "
    "and can forge members, deaths and records; and robots cannot authenticate each other, so "
    "plans, recovery requests and component states do not travel between robots (this robot "
    "works alone). The HTTP API still needs this agent's token. For a fleet, give every robot "
    "the same --key-file."
)


class Agent:
    """One robot's agent (implements `sdrpeer.api.view.AgentView`)."""

    def __init__(self, config: AgentConfig) -> None:
        self.config = config
        self.launch_policy, self.launchers_missing = offered(config.launch_policy)
        """What this robot's hosts may run: the configured launchers less those it cannot run
        here (`ros2` without ROS 2 installed), each of those with why (said at start)."""
        self.tuning: Tuning = preset(config.preset)
        """Every timer and size of this agent and its parts: the preset `config.preset` names."""
        self.events = EventLog()
        self.links = LinkTable()
        self.records: dict[str, tuple[int, RobotRecord]] = {}
        """Each other robot's record version and record, with its newest vitals laid over."""
        self._received: dict[str, tuple[int, RobotRecord]] = {}
        """Each other robot's record as it came (before vitals)."""
        self._vitals: dict[str, tuple[int, int, Vitals]] = {}
        """Each other robot's newest vitals: (record version, revision, vitals)."""
        self.metrics: Metrics | None = None
        self.api_url: str | None = None
        self.shell: GossipShell | None = None
        self._saved_offset = 0  # the cluster-time offset last written to the data dir
        self.core: Membership | None = None
        self.robot: VirtualRobot | None = None
        self.host: HostMetrics | None = None
        self.scenario: Scenario | None = None
        self.traps = TrapDetector()
        self.meter = ProcessTreeMeter(os.getpid(), max_age=METER_MAX_AGE)
        self._runner: AppRunner | None = None
        self.api_site: GuardedSite | None = None
        self._tasks: list[asyncio.Task[None]] = []
        self._started_wall = time.time()
        self._started = 0.0
        self._scenario_origin = 0.0
        """Loop time of the scenario's time 0 (`AgentConfig.scenario_start`, else the start)."""
        self.current: RobotRecord | None = None
        """This robot's latest sample, whatever was published of it."""
        self._state: tuple[RobotRecord | None, ClusterState] | None = None
        """The last cluster state made, with the own sample it was made with (None: stale)."""
        self.publisher = Publisher(min_gap=self.tuning.agent.record_gap)
        self._cpu = Average()
        """The CPU average the record carries (`sdrpeer.monitor.publish.CPU_AVERAGE_S`)."""
        self.record_json: dict[str, tuple[RobotRecord, dict[str, Any]]] = {}
        """Each robot's record as JSON, with the record it was made of (`members_view`)."""
        self.published: Counter[str] = Counter()
        """Records and vitals revisions published by this robot (`GET /v1/agent`)."""
        self._bounds_for: object = ()
        self._link_bounds = link_bounds(None)
        self._versions = (1, 0)  # (first record version of this run, reserved limit)
        self._states: dict[str, tuple[str, str]] = {}
        self._overflows = OverflowWatch()
        self._rate = {"t": 0.0, "in": 0, "out": 0, "in_s": 0.0, "out_s": 0.0}
        self.keyring: Keyring | None = None
        self.peer_tokens: list[str] = []
        """Tokens the API takes from other agents (one per cluster key; updated on reload)."""
        self.instances: InstanceManager | None = None
        """This robot's component instances (None until the deployment stack is loaded)."""
        self.coordinator: Coordinator | None = None
        self._stack: asyncio.Task[None] | None = None
        self.stopping: str | None = None
        """The stage `stop()` is in (None until it is called; "done" at the end)."""
        self.dashboard = Feed(self)
        """History and live streams of the dashboard (`sdrpeer.dashboard`)."""
        self.events.listeners.append(self.dashboard.on_event)
        self.recovery = RecoveryTally()
        """Recovery steps decided here by action, and components moved by this allocator."""
        self.events.listeners.append(self.recovery.count)
        self.priority = config.priority
        """Election priority: --priority / the config file, else the robot file's `priority:`."""
        self.discovery: Discovery | None = None
        """mDNS discovery of the fleet (`discover: true`; sdrpeer.agent.discovery)."""
        self.keys = KeyAdmin(
            config.name,
            lambda: self.keyring,
            self.use_keyring,
            self._key_peers,
            peer_client.call,
            lambda: peer_token(self.keyring.signing_key if self.keyring else None),
        )
        """The key commands (`sdrpeer key ...`): this robot's side and the fleet's."""

    @property
    def name(self) -> str:
        """This robot's name."""
        return self.config.name

    # ----------------------------------------------------------------- lifecycle
    async def start(self, *, stack_in_background: bool = False) -> None:
        """Load keys and robot facts, bind gossip and the API, write agent.json, join; then
        start the deployment stack (`_start_stack`): before returning, or, with
        `stack_in_background` (the agent process), while the API already answers."""
        cfg = self.config
        loop = asyncio.get_running_loop()
        self._started = loop.time()
        self._scenario_origin = self._started
        cfg.data_dir.mkdir(parents=True, exist_ok=True)
        if cfg.insecure:
            log.warning(INSECURE_WARNING, cfg.bind)
        else:
            assert cfg.key_file is not None
            self.keyring, source = load_ring(cfg.key_file, cfg.data_dir)
            if source != cfg.key_file:
                log.info("keys from %s (newer than %s)", source, cfg.key_file)
        self.peer_tokens[:] = peer_tokens(self.keyring.keys if self.keyring else ())
        token = load_token(cfg.data_dir, cfg.token_file)
        if cfg.robot_file is not None:
            # Only virtual robots read YAML files: real ones start without the parser.
            from sdrpeer.monitor.scenario import Scenario  # noqa: PLC0415
            from sdrpeer.monitor.virtual import RobotFile, VirtualRobot  # noqa: PLC0415

            robot_file = RobotFile.load(cfg.robot_file)
            if robot_file.name != cfg.name:
                raise ConfigError(
                    f"{cfg.robot_file}: robot file is for {robot_file.name!r}, not {cfg.name!r}"
                )
            self.robot = VirtualRobot(robot_file, self.meter.measure, start=self._started)
            if not cfg.priority:  # the flag or config file wins; else the robot file's
                self.priority = robot_file.priority
            if cfg.scenario is not None:
                self.scenario = Scenario.load(cfg.scenario, robots=[robot_file], fleet=True)
                if cfg.scenario_start is not None:  # the same clock as the lab's (and the fleet's)
                    self._scenario_origin = self._started - (time.time() - cfg.scenario_start)
        else:
            self.host = HostMetrics()
        gossip = self.tuning.gossip
        host, port = parse_hostport(cfg.bind)
        first = agent_files.seq_start(cfg.data_dir, time.time_ns() // 1000)
        codec = Codec(cfg.name, self.keyring, max_datagram=gossip.datagram_limit, seq_start=first)
        wall = self.robot.file.wall if self.robot is not None else time.time
        if self.keyring is not None:
            codec.clock.offset_ms = self._saved_offset = agent_files.load_clock_offset(cfg.data_dir)
            codec.begin_life(wall())  # what was sent to an earlier life of this robot is stale
        self.shell, addr = await open_gossip(
            host, port, codec, self._on_core_event, self._on_reject, wall=wall
        )
        self._versions = agent_files.record_versions(cfg.data_dir)
        self.core = Membership(
            cfg.name,
            addr,
            gossip,
            now=loop.time(),
            rng=random.Random(),
            first_version=self._versions[0],
        )
        self.shell.attach(self.core)
        await self._start_api(token)
        # The first record waits for the deployment stack (its election belief and plan): one
        # record per robot at start, not two, and each is spread to the whole fleet.
        self.events.add(
            time.time(),
            EventKind.AGENT_START,
            cfg.name,
            gossip=f"{addr[0]}:{addr[1]}",
            api=self.api_url,
        )
        seeds = [parse_hostport(s) for s in cfg.join]
        if seeds:
            self.shell.join(seeds)
        if cfg.discover:
            await self._start_discovery(host, addr[1])
        self._tasks.append(asyncio.create_task(self._metrics_loop()))
        self._tasks.append(asyncio.create_task(self.dashboard.run()))
        self._stack = asyncio.create_task(self._start_stack())
        if not stack_in_background:
            await self._stack
        log.info(
            "agent %s up: gossip %s:%d, api %s, preset %s, launchers %s",
            cfg.name,
            addr[0],
            addr[1],
            self.api_url,
            cfg.preset,
            ", ".join(self.launch_policy.launchers) or "none",
        )
        for name, why in self.launchers_missing.items():
            log.warning("launcher %s is configured but not offered: %s", name, why)

    async def _start_discovery(self, host: str, port: int) -> None:
        """Announce this agent and join what mDNS finds; a failure is logged, not fatal (the
        robot may still be found by others, or be given `join` addresses)."""
        from sdrpeer.agent.discovery import Discovery  # noqa: PLC0415 - only with discover on

        self.discovery = Discovery(host, port, self._on_discovered)
        try:
            await self.discovery.start()
        except (OSError, ImportError) as exc:
            log.error("discovery is on but cannot start: %r", exc)
            self.discovery = None

    def _on_discovered(self, host: str, port: int) -> None:
        """An agent found by discovery: join what was found while this robot is alone (a robot
        in the fleet leaves the joining to the newcomer, which is alone: the core keeps its join
        addresses as reconnect targets, and one that never answers, an agent of another fleet,
        would take a share of the anti-entropy rounds for good)."""
        if self.shell is None or self.core is None or self.discovery is None:
            return
        alive = {m.addr for m in self.core.members() if m.state == MemberState.ALIVE}
        alive.discard(self.core.addr)
        if alive:
            return
        configured = [parse_hostport(s) for s in self.config.join]
        found = [a for a in self.discovery.found.values() if a not in configured]
        log.info("discovery: found %s:%d, joining", host, port)
        self.shell.join([*configured, *found])

    async def _start_stack(self) -> None:
        """The deployment stack: its modules load in a worker thread while the loop serves the
        API and gossip (loading them took a third of the start-up), then the instance manager
        and the coordinator start here. Until then instance and deployment requests get 503."""
        cfg = self.config
        # The import itself runs in the thread (the loop keeps serving); the names bound here
        # are then taken from sys.modules at once.
        await asyncio.to_thread(_load_stack)
        from sdrpeer.deploy.coordinator import Coordinator  # noqa: PLC0415 - loaded above
        from sdrpeer.runtime.manager import InstanceManager  # noqa: PLC0415

        tuning = self.tuning
        instances = InstanceManager(
            cfg.data_dir,
            tuning.supervisor.with_(data_host=parse_hostport(cfg.bind)[0]),
            lambda: self._publish(force=True),
            on_fault=self._on_fault,
            on_instance_problem=self._on_fault,
            on_refused=self._on_refused,
            policy=self.launch_policy,
        )
        instances.launch_env = self._launch_env
        instances.data_keys = data_keys(self.keyring.keys) if self.keyring else ()
        instances.remote_address = self._remote_data_address
        self.coordinator = Coordinator(
            cfg.name,
            cfg.data_dir,
            instances,
            self._cluster_state,
            token=peer_token(self.keyring.signing_key if self.keyring else None),
            events=self.events,
            on_change=lambda: self._publish(force=True),
            config=tuning.deploy,
            election=tuning.election.with_(preempt=True) if cfg.preempt else tuning.election,
            recovery=tuning.recovery,
        )
        self.instances = instances
        await instances.start()
        self._publish(force=True)
        self.coordinator.start()
        assert self.core is not None
        # Written once the agent is whole: what waits for it (a lab, a test) can use every route.
        write_agent_json(cfg.data_dir, self.name, self.core.addr, self.api_url)
        trim_heap()
        log.info("agent %s ready: deployment stack loaded", self.name)

    @property
    def stack(self) -> asyncio.Task[None] | None:
        """The task that starts the deployment stack (done once the agent is whole)."""
        return self._stack

    @property
    def ready(self) -> bool:
        """Whether the deployment stack is up (`GET /healthz` says so)."""
        return self.coordinator is not None

    async def stop(self, *, leave: bool = True) -> None:
        """Leave the cluster gracefully, then close the API and the socket. `stopping` names
        the stage under way (a caller that runs out of time says what hung, then `abort()`s)."""
        self.stopping = "background tasks"
        for task in self._tasks:
            task.cancel()
        if self._stack is not None and not self._stack.done():
            self.stopping = "the deployment stack's start"
            self._stack.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._stack
        self.dashboard.close()
        if self.discovery is not None:
            self.stopping = "discovery"
            await self.discovery.stop()
        if self.coordinator is not None:
            self.stopping = "the coordinator"
            if leave:
                self.coordinator.leave()
            await self.coordinator.stop()
        if self.instances is not None:
            self.stopping = "the component hosts"
            await self.instances.stop()
        if self.shell is not None and self.core is not None and leave:
            self.stopping = "the leave message"
            self.shell.leave()
            await asyncio.sleep(self.tuning.agent.leave_wait)
        if self._runner is not None:
            self.stopping = "the API server"
            await self._runner.cleanup()
        self.stopping = "done"
        self._close_now()
        log.info("agent %s stopped", self.name)

    def abort(self) -> None:
        """Stop at once, whatever `stop()` was waiting for: SIGKILL every component host (none
        outlives the agent), close the gossip socket, remove agent.json."""
        if self.instances is not None:
            self.instances.kill_all()
        self._close_now()

    def _close_now(self) -> None:
        if self.shell is not None:
            self.shell.close()
        (self.config.data_dir / "agent.json").unlink(missing_ok=True)

    async def _start_api(self, token: str) -> None:
        host, port = parse_hostport(self.config.api)
        self._runner, self.api_site = await serve_api(
            self,
            token,
            host,
            port,
            extra_routes=[*DEPLOY_ROUTES, *DASHBOARD_ROUTES, *PORT_ROUTES, *KEY_ROUTES],
            peer_tokens=self.peer_tokens,
            limits=self.tuning.api,
        )
        self.api_url = self.api_site.name

    # ----------------------------------------------------------------- monitoring
    async def _metrics_loop(self) -> None:
        interval, cfg_dir = self.config.metrics_interval, self.config.data_dir
        loop = asyncio.get_running_loop()
        t_prev = 0.0
        while True:
            await asyncio.sleep(interval)
            now = loop.time()
            if self.scenario is not None and self.robot is not None:
                t = now - self._scenario_origin
                changes = self.scenario.changes_for(self.name, t_prev, t)
                t_prev = t
                if changes:
                    self.robot.set(now, changes)
                    self.events.add(
                        time.time(), EventKind.SCENARIO, self.name, changes=_jsonable(changes)
                    )
            if self.instances is not None:
                self.instances.sample()
            self._publish()
            offset = self.shell.codec.clock.offset_ms if self.shell is not None else 0
            self._saved_offset = agent_files.keep_clock_offset(cfg_dir, offset, self._saved_offset)
            if self.coordinator is not None and self.metrics is not None:
                self.coordinator.local.sample(self.metrics.mem_free, self.metrics.cpu_pct)

    def _sample(self, now: float) -> Metrics:
        if self.robot is not None:
            return self.robot.sample(now)
        assert self.host is not None
        return self.host.sample(now)

    def _publish(self, *, force: bool = False) -> None:
        """Sample, raise traps, and publish what the publisher decides: a new record, a vitals
        revision, or nothing."""
        if self.shell is None:
            return
        now = asyncio.get_running_loop().time()
        self.metrics = metrics = self._sample(now)
        for trap in self.traps.feed(metrics, now):
            if trap.broadcast:  # its crossing also makes a new record (a publishing boundary)
                self.shell.broadcast_event("trap", encode_trap(trap))
            self.events.add(time.time(), EventKind.TRAP, self.name, **_trap_json(trap))
        self._update_rates(now)
        infos = () if self.instances is None else self.instances.infos()
        self._log_states(infos)
        self._log_overflows(now, infos)
        coord = self.coordinator
        record = RobotRecord(
            replace(metrics, cpu_pct=round(self._cpu.add(now, metrics.cpu_pct), 1)),
            self.links.summary(now, self._bounds()),
            self.api_url,
            self.priority,
            infos,
            election=None if coord is None else coord.election.info(),
            plan=None if coord is None else coord.store.info(),
            launch=self.launch_policy,
        )
        self.current = record
        decision, version = publish(self.shell, self.publisher, now, record, force=force)
        self.published[decision] += 1
        if decision == RECORD and version >= self._versions[1]:
            limit = agent_files.reserve_record_versions(self.config.data_dir, version)
            self._versions = (self._versions[0], limit)

    def _bounds(self) -> LinkBounds:
        """The link bounds and publishing boundaries of the deployed system (kept per plan)."""
        plan = None if self.coordinator is None else self.coordinator.store.plan
        system = None if plan is None else plan.system
        # the tightest bounds of any component or connection: a link past a connection's own
        # bound is listed exactly, so the allocator and compliance see its value
        key = None if system is None else (system.recovery, system.tightest_thresholds())
        if key != self._bounds_for:
            self._bounds_for = key
            recovery, thresholds = (None, None) if key is None else key
            self.publisher.boundaries = boundaries(recovery, thresholds)
            self._link_bounds = link_bounds(thresholds)
        return self._link_bounds

    def _log_states(self, infos: tuple[InstanceInfo, ...]) -> None:
        """An `instance.state` event for every instance whose state or role changed."""
        now = {i.name: (i.state, i.role) for i in infos}
        for name, (state, role) in now.items():
            if self._states.get(name) != (state, role):
                comp = next(i.component for i in infos if i.name == name)
                self.events.add(
                    time.time(),
                    EventKind.INSTANCE_STATE,
                    self.name,
                    instance=name,
                    component=comp,
                    state=state_to_wire(state),
                    role=role,
                )
        for gone in set(self._states) - set(now):
            self.events.add(
                time.time(), EventKind.INSTANCE_STATE, self.name, instance=gone, state="gone"
            )
        self._states = now

    def _log_overflows(self, now: float, infos: tuple[InstanceInfo, ...]) -> None:
        """A `port.overflow` warning when an instance's connections start losing frames to
        full buffers (then at most one per port every 30 s while it goes on)."""
        if self.instances is None:
            return
        components = {i.name: i.component for i in infos}
        for name, ports in self.instances.port_counters().items():
            for o in self._overflows.feed(now, name, ports):
                log.warning(
                    "%s.%s: %d frames lost to full buffers (%d in all)",
                    o.instance,
                    o.port,
                    o.frames,
                    o.total,
                )
                self.events.add(
                    time.time(),
                    EventKind.PORT_OVERFLOW,
                    self.name,
                    instance=o.instance,
                    component=components.get(o.instance),
                    port=o.port,
                    frames=o.frames,
                    total=o.total,
                )
        self._overflows.keep(components)

    def _update_rates(self, now: float) -> None:
        assert self.shell is not None
        c, r = self.shell.counters, self._rate
        dt = now - r["t"]
        if dt > 0 and r["t"] > 0:
            r["in_s"] = (c["bytes_in"] - r["in"]) / dt
            r["out_s"] = (c["bytes_out"] - r["out"]) / dt
        r["t"], r["in"], r["out"] = now, c["bytes_in"], c["bytes_out"]

    # ----------------------------------------------------------------- component instances
    def reload_keys(self) -> bool:
        """Read the keys again (SIGHUP) and use them, True when they are in use: the newer of the
        key file and the ring saved in the data directory (sdrpeer.keys.store), so a hand-edited
        key file wins and a rotation done with `sdrpeer key` is kept. A file that cannot be read
        changes nothing (`keys.reload_failed` in the event log). docs/security.md tells the
        procedure by hand: add the new key second everywhere, put it first, remove the old one."""
        key_file = self.config.key_file
        if self.keyring is None or key_file is None:
            log.warning("key reload asked, but this agent runs without a key file")
            return False
        try:
            ring, source = load_ring(key_file, self.config.data_dir)
        except (ConfigError, OSError, ValueError) as exc:
            log.error("key reload failed, the old keys stay: %s", exc)
            self.events.add(time.time(), EventKind.KEYS_RELOAD_FAILED, self.name, error=str(exc))
            return False
        self.use_keyring(ring, f"reload of {source}")
        return True

    def use_keyring(self, ring: Keyring, why: str) -> None:
        """Use `ring` from now on, the first key sealing and all opening: the gossip codec takes
        it, the API accepts the peer token of every key in it, the agent presents the token of the
        sealing key, every component host gets the new data keys (sdrpeer.dataplane.auth); and it
        is saved to DATA_DIR/keyring so a restart keeps it (a failed save is logged: the ring is
        in use all the same)."""
        self.keyring = ring
        if self.shell is not None:
            self.shell.codec.keyring = ring
        self.peer_tokens[:] = peer_tokens(ring.keys)
        if self.coordinator is not None:
            self.coordinator.set_token(peer_token(ring.signing_key))
        if self.instances is not None:  # else the stack takes the new ring's keys when it starts
            self.instances.set_data_keys(data_keys(ring.keys))
        try:
            save_ring(self.config.data_dir, ring)
        except ConfigError as exc:
            log.error("%s (a restart will not keep these keys)", exc)
        ids = [k.hex() for k in ring.key_ids]
        log.info("keys in use (%s): %d key(s), signing with %s", why, len(ids), ids[0])
        self.events.add(time.time(), EventKind.KEYS_RELOADED, self.name, key_ids=ids, why=why)

    def _key_peers(self) -> tuple[dict[str, str | None], list[str]]:
        """The other alive robots' API addresses, and the members that are not alive."""
        state = self._cluster_state()
        apis = {n: r.api for n, r in state.alive.items() if n != self.name}
        missed = sorted(state.members - set(state.alive))
        return apis, missed

    def _on_fault(self, name: str, kind: str, detail: str) -> None:
        """A component fault, an instance in ERROR, or a host that died: to local recovery."""
        self.events.add(
            time.time(),
            EventKind.INSTANCE_FAULT,
            self.name,
            instance=name,
            fault=kind,
            detail=detail,
        )
        if self.coordinator is not None:
            self.coordinator.local.fault(name, kind, detail)

    def _on_refused(self, name: str, report: Refused) -> None:
        """A receiver refuses one of `name`'s outgoing connections (or takes it again)."""
        kind = EventKind.CONN_REFUSED if report.error is not None else EventKind.CONN_ACCEPTED
        detail = {"error": report.error} if report.error is not None else {}
        spec = None if self.instances is None else self.instances.desired().get(name)
        self.events.add(
            time.time(),
            kind,
            self.name,
            instance=name,
            component=None if spec is None else spec.component,
            conn=report.conn,
            sender=report.from_,
            to=report.to,
            port=report.in_port,
            count=report.count,
            **detail,
        )

    # ----------------------------------------------------------------- deployment
    def _wake_coordinator(self) -> None:
        if self.coordinator is not None:
            self.coordinator.wake()

    def _launch_env(self, spec: InstanceSpec) -> dict[str, str]:
        """A `ros2` host's fleet discovery settings (sdrpeer.ros2.env): the fleet's domain (an
        inherited ROS_DOMAIN_ID outside 0..101 is not taken), the other alive robots' addresses
        as static DDS peers; nothing for other launchers."""
        if spec.launcher != "ros2":
            return {}
        from sdrpeer.ros2.env import DOMAIN_MAX, Ros2Net, default_domain  # noqa: PLC0415

        domain = self.config.ros2_domain
        if domain is None:
            inherited = os.environ.get("ROS_DOMAIN_ID", "")
            ok = inherited.isdigit() and int(inherited) <= DOMAIN_MAX
            domain = int(inherited) if ok else default_domain("sdrpeer")
        peers: list[str] = []
        if self.core is not None:
            peers = [
                m.addr[0]
                for m in self.core.members()
                if m.state == MemberState.ALIVE and m.name != self.name
            ]
        return Ros2Net(domain, tuple(peers)).env()  # the host fixes its library path itself

    def _remote_data_address(self, instance: str) -> str | None:
        """The TCP data address another alive robot's record gives for `instance` (None: no
        record gives one): where a run-time connection from here reaches it. While it moves,
        two records may list it: the one running it ACTIVE wins."""
        found: list[tuple[bool, str]] = []
        for name, record in self._cluster_state().alive.items():
            if name == self.name:
                continue
            for info in record.instances:
                if info.name == instance and info.data:
                    found.append((info.state == LifecycleState.ACTIVE, info.data))
        return max(found, key=lambda f: f[0])[1] if found else None

    def _cluster_state(self) -> ClusterState:
        """Alive robots (ALIVE or SUSPECT; this one included) with their latest records (made
        again only after a member, record or own sample changed: the coordinator asks often)."""
        state = self._state
        if state is not None and state[0] is self.current:
            return state[1]
        alive: dict[str, RobotRecord] = {}
        members = {self.name}
        heard = {self.name}
        others = False
        if self.core is not None:
            for m in self.core.members():
                if m.name == self.name:
                    continue
                others = True
                if m.state != MemberState.LEFT:
                    members.add(m.name)
                if m.state in (MemberState.ALIVE, MemberState.SUSPECT):
                    heard.add(m.name)
                    rec = self.records.get(m.name)
                    if rec is not None:
                        alive[m.name] = rec[1]
        if self.current is not None:
            alive[self.name] = self.current
        made = ClusterState(alive, sorted(alive), frozenset(members), frozenset(heard), others)
        self._state = (self.current, made)
        return made

    def allocator_api(self) -> str | None:
        """API address of the robot this one believes holds the allocator role."""
        leader = None if self.coordinator is None else self.coordinator.election.info().leader
        rec = self._cluster_state().alive.get(leader or "")
        return None if rec is None else rec.api

    # ----------------------------------------------------------------- core events
    def _on_core_event(self, event: CoreEvent) -> None:
        wall = time.time()
        if not isinstance(event, ProbeOutcome):
            self._state = None  # a member, a record or vitals changed
        if isinstance(event, ProbeOutcome):
            self.links.observe(event.name, event.rtt, event.at)
        elif isinstance(event, RecordChanged):
            if event.name == self.name:
                return
            try:
                record = decode_record(event.payload)
            except RecordError as e:
                self.events.add(wall, EventKind.RECORD_MALFORMED, event.name, error=str(e))
                return
            old = self.records.get(event.name)
            self._received[event.name] = (event.version, record)
            self._overlay(event.name)
            self._wake_coordinator()
            if old is None or _states_of(old[1]) != _states_of(record):
                self.dashboard.poke()  # a page shows another robot's state change at once
        elif isinstance(event, VitalsChanged):
            try:
                vitals = decode_vitals(event.payload)
            except RecordError as e:
                self.events.add(wall, EventKind.VITALS_MALFORMED, event.name, error=str(e))
                return
            self._vitals[event.name] = (event.version, event.revision, vitals)
            before = self.records.get(event.name)
            self._overlay(event.name)
            after = self.records.get(event.name)
            if (
                before is not None
                and after is not None
                and self.publisher.boundaries.crossed(before[1], after[1]) is not None
            ):  # a value some decision compares with crossed its cut: judge it now, not at the
                # next tick (a crossing less than record_gap after a record comes as vitals)
                self._wake_coordinator()
        elif isinstance(event, MemberChanged):
            self._on_member(event, wall)
        elif isinstance(event, EventReceived) and event.kind == "trap":
            try:
                trap = decode_trap(event.payload)
            except RecordError as e:
                self.events.add(wall, EventKind.TRAP_MALFORMED, event.source, error=str(e))
                return
            self.events.add(wall, EventKind.TRAP, event.source, **_trap_json(trap))

    def _overlay(self, name: str) -> None:
        """records[name]: the record received, with the newest vitals of it (or of a newer
        record not received yet) laid over it; older vitals are dropped."""
        received = self._received.get(name)
        if received is None:
            return
        version, record = received
        vitals = self._vitals.get(name)
        if vitals is not None:
            if vitals[0] < version:
                del self._vitals[name]
            else:
                record = apply_vitals(record, vitals[2], same_version=vitals[0] == version)
        self.records[name] = (version, record)

    def _on_reject(self, reason: str, detail: str, count: int) -> None:
        self.events.add(
            time.time(),
            EventKind.WIRE_REJECTED,
            self.name,
            reason=reason,
            count=count,
            detail=detail,
        )

    def _on_member(self, event: MemberChanged, wall: float) -> None:
        if event.state == REAPED:
            self.records.pop(event.name, None)
            self._received.pop(event.name, None)
            self._vitals.pop(event.name, None)
            self.record_json.pop(event.name, None)
            self.links.forget(event.name)
            kind = EventKind.MEMBER_REAPED
        elif event.previous is None:
            kind = EventKind.MEMBER_JOIN
        else:
            kind = EventKind(f"member.{event.state}")
        detail: dict[str, Any] = {
            "addr": f"{event.addr[0]}:{event.addr[1]}",
            "incarnation": event.incarnation,
        }
        if event.previous is not None:
            detail["previous"] = event.previous
        self.events.add(wall, kind, event.name, **detail)
        self._wake_coordinator()
        if kind in (EventKind.MEMBER_DEAD, EventKind.MEMBER_SUSPECT, EventKind.MEMBER_LEFT):
            log.info("%s is %s (incarnation %d)", event.name, kind[7:], event.incarnation)

    # ----------------------------------------------------------------- AgentView
    @staticmethod
    def _wall_of(t: float) -> float:
        return round(time.time() - (asyncio.get_running_loop().time() - t), 3)

    def members_view(self) -> list[dict[str, Any]]:
        """Every known member with its metrics and links (see AgentView): this robot's own links
        are all listed, another robot's only those its record lists (past the bounds); every
        member's `link_summary` sums up all of its links. A dead or departed member's instances are
        shown `lost` (with their `last_state`) from the moment it is declared so: its last record
        still lists them until it is reaped."""
        if self.core is None:
            return []
        out = []
        positions = {n: r.metrics.pos for n, (_, r) in self.records.items()}
        positions[self.name] = self.metrics.pos if self.metrics else None
        for m in sorted(self.core.members(), key=lambda m: m.name):
            rec: RobotRecord | None
            if m.name == self.name:
                own = self.core.record_of(self.name)
                rec = self.current
                version = own[0] if own else 0
            else:
                version, rec = self.records.get(m.name, (0, None))
            doc = self._record_json(m.name, rec)
            if m.name == self.name:
                now = asyncio.get_running_loop().time()
                doc["links"] = {p: link_to_json(s) for p, s in self.links.snapshot(now).items()}
            for peer, link in doc["links"].items():
                d = distance(positions.get(m.name), positions.get(peer))
                link["distance_m"] = None if d is None else round(d, 2)
            state = m.state
            instances = doc.get("instances", [])
            if state in (MemberState.DEAD, MemberState.LEFT):  # its last record lists them: gone
                instances = [
                    {**i, "state": "lost", "last_state": i.get("state")} for i in instances
                ]
            out.append(
                {
                    "name": m.name,
                    "addr": f"{m.addr[0]}:{m.addr[1]}",
                    "state": state,
                    "incarnation": m.incarnation,
                    "since": self._wall_of(m.since),
                    "api": rec.api if rec is not None else None,
                    "record_version": version,
                    "vitals_revision": self._revision(m.name, version),
                    "metrics": doc["metrics"],
                    "links": doc["links"],
                    "link_summary": doc.get("link_summary"),
                    "instances": instances,
                    "launch": doc.get("launch"),
                }
            )
        return out

    def _record_json(self, name: str, rec: RobotRecord | None) -> dict[str, Any]:
        """`record_to_json(rec)`, made once per record (records are immutable: most robots'
        records do not change between two dashboard frames), copied where the view adds to it."""
        if rec is None:
            return {"metrics": None, "links": {}}
        cached = self.record_json.get(name)
        if cached is None or cached[0] is not rec:
            cached = (rec, record_to_json(rec))
            self.record_json[name] = cached
        doc = dict(cached[1])
        doc["links"] = {peer: dict(link) for peer, link in doc["links"].items()}
        return doc

    def _revision(self, name: str, version: int) -> int:
        """The vitals revision of record `version` that `name`'s entry shows (0: the record's
        own)."""
        if self.core is None:
            return 0
        vitals = self.core.vitals_of(name)
        return vitals.revision if vitals is not None and vitals.version == version else 0

    def agent_view(self) -> dict[str, Any]:
        """This agent's counters and settings (see AgentView)."""
        assert self.core is not None
        assert self.shell is not None
        c = self.shell.counters
        codec = self.shell.codec.counters
        site = self.api_site
        states = dict.fromkeys(MemberState, 0)
        for m in self.core.members():
            states[m.state] += 1
        return {
            "name": self.name,
            "addr": f"{self.core.addr[0]}:{self.core.addr[1]}",
            "api": self.api_url,
            "version": __version__,
            "uptime_s": round(time.time() - self._started_wall, 3),
            "insecure": self.keyring is None,
            "preset": self.config.preset,
            "launchers": {
                "offered": list(self.launch_policy.launchers),
                "not_offered": dict(self.launchers_missing),
            },
            "health_score": self.core.health_score,
            "messages": {
                "in": c["messages_in"],
                "out": c["messages_out"],
                "bytes_in": c["bytes_in"],
                "bytes_out": c["bytes_out"],
                "bytes_in_per_s": round(self._rate["in_s"], 1),
                "bytes_out_per_s": round(self._rate["out_s"], 1),
                "sent_by_kind": dict(sorted(self.shell.sent_by_kind.items())),
            },
            "rejected": {r: codec.get(r, 0) for r in REASONS},
            "api_connections": {
                "open": 0 if site is None else site.open_connections(),
                **(dict.fromkeys(COUNTERS, 0) if site is None else site.table.counters),
            },
            "clock": {
                "offset_ms": self.shell.codec.clock.offset_ms,
                "advanced": codec.get("clock_advanced", 0),
                "nudges": c["clock_nudges"],
            },
            "members": states,
            "gossip": dict(self.core.counters),
            "published": {k: self.published[k] for k in ("record", "vitals")},
        }

    def deploy_view(self) -> dict[str, Any]:
        """Election, recovery and handoff counters, event counts (the Prometheus families)."""
        coord = self.coordinator
        info = None if coord is None else coord.election.info()
        return {
            "election": {
                "epoch": 0 if info is None else info.epoch,
                "leader": None if info is None else info.leader,
            },
            "recovery_actions": dict(self.recovery.actions),
            "recovery_moves": dict(self.recovery.moves),
            "handoff": {} if coord is None else dict(coord.handoff.counters),
            "events": dict(self.events.counts),
            "dashboard_streams": self.dashboard.hub.clients,
        }

    def events_view(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        """Event log entries after `since` (see AgentView)."""
        return self.events.since(since, limit)

    def status_view(self) -> dict[str, Any] | None:
        """The deployment status (GET /v1/status), for the dashboard."""
        return None if self.coordinator is None else self.coordinator.status(time.time())

    def set_virtual(self, changes: dict[str, Any]) -> dict[str, Any]:
        """Change this virtual robot's facts live and publish them at once, as the publisher
        decides: a new record when a decision input changed, else vitals (see AgentView)."""
        if self.robot is None:
            raise ConfigError(f"{self.name} reads real hardware (no --robot-file): nothing to set")
        self.robot.set(asyncio.get_running_loop().time(), changes)
        self.events.add(time.time(), EventKind.ROBOT_SET, self.name, changes=_jsonable(changes))
        self._publish()
        assert self.metrics is not None
        return metrics_to_json(self.metrics)


def _load_stack() -> None:
    """Import the deployment stack (run in a worker thread by `Agent._start_stack`)."""
    import sdrpeer.deploy.coordinator  # noqa: PLC0415
    import sdrpeer.runtime.manager  # noqa: F401, PLC0415


def _jsonable(changes: dict[str, Any]) -> dict[str, Any]:
    return {k: (list(v) if isinstance(v, tuple) else v) for k, v in changes.items()}


def _trap_json(trap: Any) -> dict[str, Any]:
    return {
        "metric": trap.metric,
        "value": trap.value,
        "threshold": trap.threshold,
        "state": trap.state,
    }


def _states_of(record: RobotRecord) -> list[tuple[str, str, str]]:
    return [(i.name, i.state, i.role) for i in record.instances]
