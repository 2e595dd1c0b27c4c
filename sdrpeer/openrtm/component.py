"""The sdrpeer Component that stands for a hosted RT-Component (built from its port profile).

How it works: `component_class(runtime)` makes a `Component` subclass named after the RTC's type
with one sdrpeer port per DataPort (same name, same direction; typed `Pose`/`Velocity` where
sdrpeer.openrtm.values maps the data type), one `str` Param per configuration parameter of the
RTC's spec (`conf.default.*`, its default the spec's) and `execution = Periodic(hz=...)` at the
RTC's execution rate. sdrpeer's runner then drives the RTC through its execution context:

| sdrpeer                 | the RTC (OpenRTM)                                                 |
|-------------------------|-------------------------------------------------------------------|
| initialize              | nothing more: `onInitialize` ran when the host created the RTC    |
| activate / deactivate   | `activate_component` / `deactivate_component` (onActivated, ...)  |
| each period, ACTIVE     | sdrpeer's InPort frames into the RTC's InPorts, one `tick()`      |
|                         | (onExecute), the RTC's OutPort data onto sdrpeer's OutPorts       |
| each period in ERROR    | one `tick()` (onError)                                            |
| reset                   | `reset_component` (onReset)                                       |
| finalize                | the RTC exits (onFinalize), the manager shuts down                |
| set params              | its active configuration set (as rtconf), applied after a period  |

A callback whose RTC call does not end in the expected state raises `RtcError`, so the runner
moves to ERROR and the agent's recovery acts: `onExecute` returning anything but RTC_OK, an
`onActivated` that fails, an RTC found in ERROR_STATE. The RTC's callbacks run on the host's loop
thread, as a plain `on_execute` of an SDK component does: a slow `onExecute` delays the control
channel and the heartbeats by as much, and one that never returns stops them, so the agent's
watchdog kills the host and recovery replaces it (the host is "hung", as any other).
"""

from __future__ import annotations

import logging
from typing import Any, ClassVar

import RTC

from sdrpeer.errors import RtcError
from sdrpeer.openrtm.runtime import RtcRuntime
from sdrpeer.openrtm.values import MAPPED_TYPES, from_sdrpeer, to_sdrpeer
from sdrpeer.sdk import Component, InPort, OutPort, Param
from sdrpeer.sdk.errors import ComponentError
from sdrpeer.sdk.execution import Periodic

log = logging.getLogger("sdrpeer.openrtm.component")

MAX_INPUT_PER_PERIOD = 1024
"""Frames taken from one sdrpeer InPort per period (the rest wait for the next period)."""


class RtcComponent(Component):
    """Base of the classes `component_class` builds; `runtime` is set on each of them."""

    runtime: ClassVar[RtcRuntime]

    def _check(self, what: str, ret: Any, want: Any) -> None:
        state = self.runtime.state()
        if ret != RTC.RTC_OK or state != want:
            raise RtcError(f"{what}: {self.runtime.type_name} answered {ret}, now {state}")

    def _forward_out(self) -> None:
        for port, data in self.runtime.take():
            try:
                self.outport(port).write(to_sdrpeer(data, self._types[port]))
            except Exception as exc:
                log.warning("%s: %s: value not forwarded: %s", self.instance_name, port, exc)

    def _inputs(self) -> list[tuple[str, Any]]:
        out: list[tuple[str, Any]] = []
        for port, repo in self._types.items():
            if port not in self._in_names:
                continue
            source = self.inport(port)
            for _ in range(MAX_INPUT_PER_PERIOD):
                if not source.is_new():
                    break
                value = source.get_nowait()
                try:
                    out.append((port, from_sdrpeer(value, repo)))
                except (ValueError, TypeError) as exc:  # a frame of the wrong shape: dropped
                    log.warning(
                        "%s: %s: frame not written to the RTC: %s", self.instance_name, port, exc
                    )
        return out

    def _write_and_tick(self, inputs: list[tuple[str, Any]]) -> None:
        for port, data in inputs:
            self.runtime.write(port, data)
        self.runtime.tick()

    def on_activated(self) -> None:
        """activate_component: onActivated and the first onExecute."""
        ret = self.runtime.activate()
        self._forward_out()
        self._check("activate", ret, RTC.ACTIVE_STATE)
        if self.runtime.failed():
            raise RtcError(
                f"{self.runtime.type_name}.onExecute returned {self.runtime.last_result}"
            )

    def on_execute(self) -> None:
        """sdrpeer's frames into the RTC, one onExecute, the RTC's data out."""
        self._write_and_tick(self._inputs())
        self._forward_out()
        if self.runtime.failed():
            raise RtcError(
                f"{self.runtime.type_name}.onExecute returned {self.runtime.last_result}"
            )
        state = self.runtime.state()
        if state != RTC.ACTIVE_STATE:
            raise RtcError(f"{self.runtime.type_name} is {state}")

    def on_aborting(self) -> None:
        """The context's next tick moves the RTC to ERROR (onAborting) if it is not there."""
        if self.runtime.state() != RTC.ERROR_STATE:
            self.runtime.tick()
            self._forward_out()

    def on_error(self) -> None:
        """One tick in ERROR: onError."""
        self.runtime.tick()
        self._forward_out()

    def on_deactivated(self) -> None:
        """deactivate_component: onDeactivated."""
        if self.runtime.state() == RTC.ACTIVE_STATE:
            ret = self.runtime.deactivate()
            self._forward_out()
            self._check("deactivate", ret, RTC.INACTIVE_STATE)

    def on_reset(self) -> None:
        """reset_component: onReset."""
        ret = self.runtime.reset()
        self._forward_out()
        self._check("reset", ret, RTC.INACTIVE_STATE)

    def on_params_changed(self, changed: dict[str, Any]) -> None:
        """New configuration values into the RTC's active set (taken after its next period)."""
        self.runtime.configure({k: str(v) for k, v in changed.items()})

    def on_finalize(self) -> None:
        """The RTC exits (onFinalize); the manager shuts down."""
        self.runtime.close()

    _types: ClassVar[dict[str, str]] = {}
    _in_names: ClassVar[frozenset[str]] = frozenset()


def component_class(runtime: RtcRuntime) -> type[RtcComponent]:
    """The Component subclass standing for `runtime`'s RTC (ComponentError on a port or
    parameter name sdrpeer cannot take)."""
    attrs: dict[str, Any] = {
        "__module__": __name__,
        "__doc__": f"The RT-Component {runtime.type_name}, hosted by sdrpeer.openrtm.",
        "runtime": runtime,
        "execution": Periodic(hz=runtime.rate),
        "_types": {p.name: p.data_type for p in runtime.ports},
        "_in_names": frozenset(p.name for p in runtime.ports if p.direction == "in"),
    }
    for port in runtime.ports:
        if not port.name.isidentifier() or port.name in attrs:
            raise ComponentError(f"{runtime.type_name}: port name {port.name!r} is not usable")
        doc = f"{port.data_type} ({'RTC InPort' if port.direction == 'in' else 'RTC OutPort'})"
        kind = MAPPED_TYPES.get(port.data_type)
        attrs[port.name] = (
            InPort(doc, type=kind) if port.direction == "in" else OutPort(doc, type=kind)
        )
    for name, default in runtime.conf_defaults.items():
        if not name.isidentifier() or name in attrs:
            raise ComponentError(f"{runtime.type_name}: parameter name {name!r} is not usable")
        attrs[name] = Param(str, default, doc=f"configuration parameter conf.default.{name}")
    return type(runtime.type_name, (RtcComponent,), attrs)
