"""One unmodified RT-Component in this process: its OpenRTM manager, its execution context, a
bridge RTC whose ports are connected to its DataPorts.

How it works: `start_manager` starts OpenRTM-aist's manager in-process with no naming service,
no logger file, no shutdown when components go, its ORB on loopback, and the synchronous
execution context (`OpenHRPExecutionContext`: nothing runs until `tick()` is called) as every
component's. `load_rtc_module` imports the RTC's module (a file or a module name) and finds its
`XxxInit(manager)` function, which registers the factory as any rtcd would. `RtcRuntime` then
creates the RTC (its `onInitialize` runs: its ports exist afterwards), reads its ports' profiles
(`port.port_type`, `dataport.data_type`) and creates one more RTC in the process, the *bridge*,
with a mirror port per DataPort: an InPort for each of the RTC's OutPorts, an OutPort for each
InPort, each connected to its RTC port by an ordinary OpenRTM connector (`corba_cdr`, push,
flush: a colocated CORBA call, no socket). The RTC therefore sees exactly what it sees in an
OpenRTM system (its buffers, `isNew()`, the connector listeners it registered); nothing of its
port objects is touched.

Everything then happens in `RtcRuntime` calls made by one thread at a time (the sdrpeer
component of sdrpeer.openrtm.component serialises them): `write(port, value)` writes a value into
the bridge OutPort connected to the RTC's InPort `port` (it lands in that InPort's buffer at
once), `tick()` runs one period of the execution context (`onExecute`, or `onError` in ERROR, after
any pending state change), `take()` returns what the RTC's OutPorts wrote since the last call,
read from the bridge's InPorts. `activate`/`deactivate`/`reset` call the execution context's
`activate_component` etc. and `configure` sets configuration parameters through the RTC's
SDO configuration interface (as rtconf does); the synchronous context carries out a change with
one tick (OpenRTM's own behaviour: the activating tick also runs the first `onExecute`).
`state()` is the RTC's state in its context; `failed()` says whether the last `onExecute`
returned something other than RTC_OK (the context moves the RTC to ERROR on its next tick).
`close()` has the RTC exit (`onFinalize`) and shuts the manager down.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import logging
import os
import sys
from collections.abc import Callable
from dataclasses import dataclass
from types import ModuleType
from typing import Any

import OpenRTM_aist
import RTC

from sdrpeer.errors import LoadError
from sdrpeer.openrtm.values import default_value, descriptor

log = logging.getLogger("sdrpeer.openrtm.runtime")

EC_TYPE = "OpenHRPExecutionContext"
DEFAULT_RATE = 1000.0
"""OpenRTM's default execution rate (`exec_cxt.periodic.rate`), used when the spec has none."""
BRIDGE_BUFFER = 256
"""Frames the bridge's InPorts hold between two ticks (the RTC's writes of one period)."""

MANAGER_OPTIONS: tuple[tuple[str, str], ...] = (
    ("naming.enable", "NO"),
    ("logger.enable", "NO"),
    ("manager.shutdown_on_nortcs", "NO"),
    ("manager.shutdown_auto", "NO"),
    ("manager.corba_servant", "YES"),
    ("timer.enable", "NO"),
    ("exec_cxt.periodic.type", EC_TYPE),
    ("corba.endpoints", "giop:tcp:127.0.0.1:"),
)
"""The manager's configuration (rtc.conf keys): no naming service, the ORB on loopback only, the
synchronous execution context."""


@dataclass(frozen=True, slots=True)
class RtcPort:
    """One DataPort of the RTC."""

    name: str
    """The port's name without the instance prefix (`Counter0.count` -> `count`)."""
    direction: str
    """`in` (an RTC InPort: sdrpeer writes into it) or `out` (an RTC OutPort)."""
    data_type: str
    """The IDL repository id of its data (`IDL:RTC/TimedLong:1.0`)."""


def start_manager() -> Any:
    """OpenRTM's manager, started in this process (its ORB threads in the background)."""
    argv = [sys.argv[0] or "sdrpeer-openrtm"]
    for key, value in MANAGER_OPTIONS:
        argv += ["-o", f"{key}:{value}"]
    manager = OpenRTM_aist.Manager.init(argv)
    manager.activateManager()
    manager.runManager(True)
    return manager


def load_rtc_module(target: str) -> tuple[str, Callable[[Any], None]]:
    """(the RTC's type name, its `XxxInit(manager)`) from `where[:TypeName]`; LoadError if not."""
    where, sep, name = target.rpartition(":")
    if not (sep and where and name.isidentifier()):
        where, name = target, ""
    module = _load(target, where)
    inits = {
        n[: -len("Init")]: f
        for n, f in vars(module).items()
        if n.endswith("Init")
        and n != "MyModuleInit"
        and len(n) > 4
        and inspect.isfunction(f)
        and f.__module__ == module.__name__
    }
    if name:
        if name not in inits:
            raise LoadError(f"{target}: {where} defines no {name}Init(manager)")
        return name, inits[name]
    if len(inits) != 1:
        found = ", ".join(f"{n}Init" for n in inits) or "none"
        raise LoadError(
            f"{target}: expected one XxxInit(manager) in {where}, found {found}; "
            f"name it: {where}:TypeName"
        )
    return next(iter(inits.items()))


def _load(target: str, where: str) -> ModuleType:
    try:
        if where.endswith(".py") or os.sep in where:
            path = os.path.abspath(where)
            if not os.path.isfile(path):
                raise LoadError(f"{target}: no such file {path}")
            sys.path.insert(0, os.path.dirname(path))
            stem = os.path.splitext(os.path.basename(path))[0]
            spec = importlib.util.spec_from_file_location(stem, path)
            if spec is None or spec.loader is None:
                raise LoadError(f"{target}: {path} is not a loadable Python file")
            module = importlib.util.module_from_spec(spec)
            sys.modules[stem] = module
            spec.loader.exec_module(module)
            return module
        return importlib.import_module(where)
    except LoadError:
        raise
    except Exception as exc:
        raise LoadError(f"{target}: import failed: {type(exc).__name__}: {exc}") from exc


class _Bridge(OpenRTM_aist.DataFlowComponentBase):  # type: ignore[misc]
    """The RTC whose ports mirror the hosted RTC's; never activated, only its ports are used."""


BRIDGE_SPEC = [
    "implementation_id", "SdrpeerBridge", "type_name", "SdrpeerBridge",
    "description", "sdrpeer's end of an RTC's DataPorts", "version", "1.0",
    "vendor", "sdrpeer", "category", "sdrpeer", "activity_type", "PERIODIC",
    "kind", "DataFlowComponent", "max_instance", "0", "language", "Python",
    "lang_type", "SCRIPT", "",
]  # fmt: skip


class RtcRuntime:
    """The RTC, its execution context and the bridge (see the module's docstring)."""

    def __init__(self, manager: Any, target: str, params: dict[str, str]) -> None:
        self.manager = manager
        self.type_name, init = load_rtc_module(target)
        init(manager)
        spec = self._spec(target)
        rate = spec.getProperty("exec_cxt.periodic.rate") or str(DEFAULT_RATE)
        self.conf_defaults: dict[str, str] = {}
        conf = spec.findNode("conf.default")
        if conf is not None:
            for key in conf.propertyNames():
                self.conf_defaults[key] = conf.getProperty(key)
        args = [f"exec_cxt.periodic.rate={rate}"]
        args += [f"conf.default.{k}={v}" for k, v in params.items()]
        self.rtc = manager.createComponent(f"{self.type_name}?{'&'.join(args)}")
        if self.rtc is None:
            raise LoadError(
                f"{target}: OpenRTM could not create {self.type_name} "
                f"(its onInitialize failed or its factory refused)"
            )
        self.ref = self.rtc.getObjRef()
        contexts = self.rtc.get_owned_contexts()
        if not contexts:
            raise LoadError(f"{target}: {self.type_name} has no execution context")
        self.ec_ref = contexts[0]
        self.ec = manager.getPOA().reference_to_servant(self.ec_ref)
        self.rate = float(self.ec_ref.get_rate())
        self._last_ret = RTC.RTC_OK
        self.rtc.addPostComponentActionListener(
            OpenRTM_aist.PostComponentActionListenerType.POST_ON_EXECUTE, self._executed
        )
        self.ports = self._read_ports()
        self._bridge_ports: dict[str, Any] = {}
        self._bridge = self._connect_bridge()

    def _spec(self, target: str) -> Any:
        for profile in self.manager.getFactoryProfiles():
            if profile.getProperty("implementation_id") == self.type_name:
                return profile
        raise LoadError(
            f"{target}: {self.type_name}Init registered no factory "
            f"of implementation_id {self.type_name!r}"
        )

    def _executed(self, ec_id: int, ret: Any) -> None:
        self._last_ret = ret

    def _read_ports(self) -> list[RtcPort]:
        out: list[RtcPort] = []
        for ref in self.rtc.get_ports():
            profile = ref.get_port_profile()
            props = {nv.name: nv.value.value() for nv in profile.properties}
            kind = props.get("port.port_type")
            if kind not in ("DataInPort", "DataOutPort"):
                log.warning(
                    "%s: port %s (%s) is not a DataPort: not mapped",
                    self.type_name,
                    profile.name,
                    kind,
                )
                continue
            out.append(
                RtcPort(
                    name=profile.name.rpartition(".")[2],
                    direction="in" if kind == "DataInPort" else "out",
                    data_type=str(props.get("dataport.data_type", "")),
                )
            )
        return out

    def _connect_bridge(self) -> Any:
        profile = OpenRTM_aist.Properties(defaults_str=BRIDGE_SPEC)
        self.manager.registerFactory(profile, _Bridge, OpenRTM_aist.Delete)
        bridge = self.manager.createComponent("SdrpeerBridge")
        if bridge is None:
            raise LoadError("OpenRTM could not create the bridge component")
        rtc_ports = {r.get_port_profile().name.rpartition(".")[2]: r for r in self.rtc.get_ports()}
        for port in self.ports:
            data = default_value(descriptor(port.data_type))
            mirror: Any
            if port.direction == "out":
                mirror = OpenRTM_aist.InPort(f"from_{port.name}", data)
                bridge.addInPort(f"from_{port.name}", mirror)
            else:
                mirror = OpenRTM_aist.OutPort(f"to_{port.name}", data)
                bridge.addOutPort(f"to_{port.name}", mirror)
            props = OpenRTM_aist.Properties()
            for key, value in (
                ("dataport.interface_type", "corba_cdr"),
                ("dataport.dataflow_type", "push"),
                ("dataport.subscription_type", "flush"),
            ):
                props.setProperty(key, value)
            if port.direction == "out":
                props.setProperty("dataport.buffer.length", str(BRIDGE_BUFFER))
                props.setProperty("dataport.inport.buffer.length", str(BRIDGE_BUFFER))
            ret = OpenRTM_aist.CORBA_RTCUtil.connect(
                f"sdrpeer_{port.name}", props, mirror.getPortRef(), rtc_ports[port.name]
            )
            if ret != RTC.RTC_OK:
                raise LoadError(
                    f"{self.type_name}.{port.name}: connecting the bridge failed: {ret}"
                )
            self._bridge_ports[port.name] = mirror
        return bridge

    # -- used by one thread at a time -----------------------------------------------------

    def write(self, port: str, data: Any) -> None:
        """Put `data` (an IDL value) into the RTC's InPort `port`."""
        self._bridge_ports[port].write(data)

    def take(self) -> list[tuple[str, Any]]:
        """(port, IDL value) for everything the RTC's OutPorts wrote since the last call."""
        out: list[tuple[str, Any]] = []
        for port in self.ports:
            if port.direction == "out":
                mirror = self._bridge_ports[port.name]
                for _ in range(BRIDGE_BUFFER):
                    if not mirror.isNew():
                        break
                    out.append((port.name, mirror.read()))
        return out

    def tick(self) -> None:
        """One period of the execution context: pending state changes, then onExecute (onError in
        ERROR), then onStateUpdate (its configuration updated). What `OpenHRPExecutionContext.tick`
        does, without the sleep it takes once per 1000 ticks to keep its own period (sdrpeer's
        context keeps the period; that sleep would stall the host's loop at low rates)."""
        self._last_ret = RTC.RTC_OK
        if self.ec.isRunning():
            self.ec.invokeWorkerPreDo()
            self.ec.invokeWorkerDo()
            self.ec.invokeWorkerPostDo()

    @property
    def last_result(self) -> Any:
        """What the last onExecute returned (RTC_OK before the first)."""
        return self._last_ret

    def failed(self) -> bool:
        """Whether the last onExecute returned something other than RTC_OK."""
        return bool(self._last_ret != RTC.RTC_OK)

    def configure(self, values: dict[str, str]) -> None:
        """Set configuration parameters in the RTC's active set, as rtconf does; the RTC's bound
        variables take them after its next execution (`on_state_update`)."""
        for name, value in values.items():
            OpenRTM_aist.CORBA_RTCUtil.set_active_configuration(self.ref, name, value)

    def state(self) -> Any:
        """The RTC's LifeCycleState in its execution context."""
        return self.ec_ref.get_component_state(self.ref)

    def activate(self) -> Any:
        """`activate_component` (one tick: onActivated, then the first onExecute)."""
        return self.ec_ref.activate_component(self.ref)

    def deactivate(self) -> Any:
        """`deactivate_component` (onDeactivated)."""
        return self.ec_ref.deactivate_component(self.ref)

    def reset(self) -> Any:
        """`reset_component` (onReset)."""
        return self.ec_ref.reset_component(self.ref)

    def close(self) -> None:
        """The RTC exits (onFinalize) and the manager shuts down."""
        try:
            self.rtc.exit()
        finally:
            self.manager.shutdown()
