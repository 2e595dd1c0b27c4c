"""The `Component` base class: declared ports and params, lifecycle callbacks, fault reports.

How it works: a subclass declares `OutPort`/`InPort`/`Param` class attributes, service ports
(`ServiceProvider`/`ServiceConsumer`, sdrpeer.sdk.services) and an `execution` context;
`__init_subclass__` collects them (in declaration order, inherited ones first) and checks the
declaration, so a mistake fails at import with the class and attribute named. Each instance gets
its own runtime ports and param values. The callbacks below are no-ops to override, each either
a plain method or `async def`; `ComponentRunner` (sdrpeer.sdk.runner) calls them around the
lifecycle transitions of sdrpeer.sdk.lifecycle. `report_fault` and its three shorthands hand a
fault to the runner (sdrpeer.sdk.faults: which kinds also move to ERROR); `on_snapshot`/
`on_restore` carry the working state to a new instance (sdrpeer.sdk.handoff).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any, ClassVar, Final

from sdrpeer.sdk.errors import ComponentError, ParamError, PortError
from sdrpeer.sdk.execution import ExecutionContext, OnInput, Periodic, Stepped
from sdrpeer.sdk.faults import FAULT_KINDS, FaultHook, check_kind
from sdrpeer.sdk.params import Param, ParamInfo
from sdrpeer.sdk.ports import InPort, InPortRuntime, OutPort, OutPortRuntime, PortInfo
from sdrpeer.sdk.services import (
    ServiceCaller,
    ServiceConsumer,
    ServiceInfo,
    ServiceProvider,
    ServiceProviderRuntime,
)

__all__ = ["FAULT_KINDS", "Component", "FaultHook"]

_INSTANCE_ATTRS: Final = frozenset({"instance_name", "log", "last_error"})


class Component:
    """Base class of every sdrpeer component; override the `on_*` callbacks you need."""

    execution: ClassVar[ExecutionContext] = Periodic(hz=10.0)
    _sdk_ports: ClassVar[dict[str, InPort | OutPort]] = {}
    _sdk_params: ClassVar[dict[str, Param[Any]]] = {}
    _sdk_services: ClassVar[dict[str, ServiceProvider | ServiceConsumer]] = {}
    _sdk_handlers: ClassVar[dict[str, dict[str, str]]] = {}

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        ports: dict[str, InPort | OutPort] = {}
        params: dict[str, Param[Any]] = {}
        services: dict[str, ServiceProvider | ServiceConsumer] = {}
        for klass in reversed(cls.__mro__):
            for name, value in vars(klass).items():
                ports.pop(name, None)
                params.pop(name, None)
                services.pop(name, None)
                if isinstance(value, InPort | OutPort):
                    ports[name] = value
                elif isinstance(value, Param):
                    params[name] = value
                elif isinstance(value, ServiceProvider | ServiceConsumer):
                    services[name] = value
        for name in (*ports, *params, *services):
            if name.startswith("_") or name in vars(Component) or name in _INSTANCE_ATTRS:
                raise ComponentError(f"{cls.__qualname__}.{name}: name reserved by Component")
        for name, p in params.items():
            p.check()
            hook = p.on_change
            if isinstance(hook, str) and not callable(getattr(cls, hook, None)):
                raise ComponentError(
                    f"{cls.__qualname__}.{name}: on_change method {hook!r} is not defined"
                )
        cls._sdk_ports = ports
        cls._sdk_params = params
        cls._sdk_services = services
        cls._sdk_handlers = {
            n: s.handlers(cls) for n, s in services.items() if isinstance(s, ServiceProvider)
        }
        cls._check_execution()

    @classmethod
    def _check_execution(cls) -> None:
        ex = cls.execution
        where = f"{cls.__qualname__}.execution"
        if isinstance(ex, OnInput):
            if not isinstance(cls._sdk_ports.get(ex.port), InPort):
                raise ComponentError(f"{where}: OnInput({ex.port!r}) names no InPort of the class")
        elif isinstance(ex, Periodic):
            if ex.param is not None:
                p = cls._sdk_params.get(ex.param)
                if p is None or p.type not in (int, float):
                    raise ComponentError(
                        f"{where}: Periodic(param={ex.param!r}) names no int/float Param"
                    )
        elif not isinstance(ex, Stepped):
            raise ComponentError(
                f"{where}: expected Periodic(...), OnInput(...) or Stepped(), got {ex!r}"
            )

    def __init__(self, name: str | None = None, params: Mapping[str, Any] | None = None) -> None:
        cls = type(self)
        self.instance_name: str = name or cls.__name__
        """The instance name (SDRPEER_INSTANCE), e.g. `CameraRTC2`."""
        self.log: logging.Logger = logging.getLogger(f"sdrpeer.component.{self.instance_name}")
        """A logger named after the instance."""
        self.last_error: str | None = None
        """The text of the last callback failure (set by the runner), or None."""
        self._param_values: dict[str, Any] = {n: p.default for n, p in cls._sdk_params.items()}
        self._ports: dict[str, InPortRuntime | OutPortRuntime] = {
            n: d.make() for n, d in cls._sdk_ports.items()
        }
        self._services: dict[str, ServiceProviderRuntime | ServiceCaller] = {
            n: d.make(self, cls._sdk_handlers[n]) if isinstance(d, ServiceProvider) else d.make()
            for n, d in cls._sdk_services.items()
        }
        self._fault_hook: FaultHook | None = None
        if params:
            self._param_values.update(self.convert_params(params))

    # -- metadata --------------------------------------------------------------------------

    @classmethod
    def ports(cls) -> dict[str, PortInfo]:
        """The declared ports by name, in declaration order."""
        return {n: d.info() for n, d in cls._sdk_ports.items()}

    @classmethod
    def params(cls) -> dict[str, ParamInfo]:
        """The declared params by name, in declaration order."""
        return {n: p.info() for n, p in cls._sdk_params.items()}

    @classmethod
    def port_names(cls) -> dict[str, list[str]]:
        """`{"in": [...], "out": [...]}` as sent in the control channel's `hello`."""
        ports = cls._sdk_ports.items()
        return {
            "in": [n for n, d in ports if isinstance(d, InPort)],
            "out": [n for n, d in ports if isinstance(d, OutPort)],
        }

    @classmethod
    def service_ports(cls) -> dict[str, ServiceInfo]:
        """The declared service ports by name (providers and consumers), in declaration order."""
        return {n: d.info() for n, d in cls._sdk_services.items()}

    # -- instance state --------------------------------------------------------------------

    def param_values(self) -> dict[str, Any]:
        """The current value of every param (a copy)."""
        return dict(self._param_values)

    def convert_params(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Every value converted to its param's type; ParamError on the first bad name or value."""
        known = type(self)._sdk_params
        out: dict[str, Any] = {}
        for name, value in values.items():
            p = known.get(name)
            if p is None:
                names = ", ".join(known) or "none"
                raise ParamError(name, "a declared param", detail=f"unknown param (known: {names})")
            out[name] = p.convert(value)
        return out

    def inport(self, name: str) -> InPortRuntime:
        """The runtime InPort called `name`; PortError if there is none."""
        port = self._ports.get(name)
        if not isinstance(port, InPortRuntime):
            raise PortError(f"{self.instance_name}: no in-port {name!r} (in: {self._names('in')})")
        return port

    def outport(self, name: str) -> OutPortRuntime:
        """The runtime OutPort called `name`; PortError if there is none."""
        port = self._ports.get(name)
        if not isinstance(port, OutPortRuntime):
            raise PortError(
                f"{self.instance_name}: no out-port {name!r} (out: {self._names('out')})"
            )
        return port

    def provider(self, name: str) -> ServiceProviderRuntime:
        """The provided service called `name`; PortError if there is none."""
        port = self._services.get(name)
        if not isinstance(port, ServiceProviderRuntime):
            raise PortError(f"{self.instance_name}: no provided service {name!r}")
        return port

    def consumer(self, name: str) -> ServiceCaller:
        """The required service called `name`; PortError if there is none."""
        port = self._services.get(name)
        if not isinstance(port, ServiceCaller):
            raise PortError(f"{self.instance_name}: no required service {name!r}")
        return port

    def port_counters(self) -> dict[str, dict[str, int]]:
        """Port name -> counters, as sent in the control channel's `heartbeat`."""
        out = {n: p.counters() for n, p in self._ports.items()}
        for n, service in self._services.items():
            out[n] = service.counters()
        return out

    # -- faults (sdrpeer.sdk.faults): callable from any callback or thread --------------------

    def report_fault(self, kind: str, detail: str = "") -> None:
        """Tell the agent about a fault (kinds in FAULT_KINDS); some also move to ERROR."""
        check_kind(kind)
        self.log.warning("fault %s: %s", kind, detail)
        if self._fault_hook is not None:
            self._fault_hook(kind, str(detail))

    def hardware_failure(self, detail: str = "") -> None:
        """A device failed or disconnected: report it and move to ERROR (through on_aborting)."""
        self.report_fault("hardware_failure", detail)

    def abnormal_behaviour(self, detail: str = "") -> None:
        """The robot behaves abnormally: report it; the component keeps its state."""
        self.report_fault("abnormal_behaviour", detail)

    def emergency_stop(self, detail: str = "") -> None:
        """Emergency stop: report it and move to ERROR (on_aborting makes the hardware safe)."""
        self.report_fault("emergency_stop", detail)

    def _names(self, kind: str) -> str:
        return ", ".join(type(self).port_names()[kind]) or "none"

    # -- callbacks to override (sync or async) ---------------------------------------------

    def on_initialize(self) -> Any:
        """CREATED -> INACTIVE: acquire resources (open devices, load models)."""

    def on_startup(self) -> Any:
        """The execution context started (right after `on_initialize`; OpenRTM's onStartup)."""

    def on_shutdown(self) -> Any:
        """The execution context stops (at finalize, before `on_finalize`; onShutdown)."""

    def on_rate_changed(self, hz: float) -> Any:
        """A `Periodic(param=...)` rate changed while running (OpenRTM's onRateChanged)."""

    def on_activated(self) -> Any:
        """INACTIVE -> ACTIVE: start working."""

    def on_execute(self) -> Any:
        """One period (or one input frame) of work, only while ACTIVE."""

    def on_deactivated(self) -> Any:
        """ACTIVE -> INACTIVE: stop working (resources stay)."""

    def on_aborting(self) -> Any:
        """ACTIVE -> ERROR: a callback failed; put the hardware in a safe state."""

    def on_error(self) -> Any:
        """Once per execution period while in ERROR; keep it cheap."""

    def on_reset(self) -> Any:
        """ERROR -> INACTIVE: recover from the error."""

    def on_finalize(self) -> Any:
        """-> FINALIZED: release everything; the host exits afterwards."""

    def on_params_changed(self, changed: dict[str, Any]) -> Any:
        """Params changed while running; `changed` maps each changed name to its new value."""

    # -- state handoff (sdrpeer.sdk.handoff) -------------------------------------------------

    def on_snapshot(self) -> Any:
        """The working state a new instance needs to continue (msgpack-able); None: nothing."""
        return None

    def on_restore(self, state: Any) -> Any:
        """Take over `state` from an earlier instance's `on_snapshot`; raise to refuse it."""
