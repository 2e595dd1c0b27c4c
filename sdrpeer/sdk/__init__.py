"""The component SDK: write an sdrpeer component the way you would an OpenRTM-aist RTC.

How it works: subclass `Component`, declare `OutPort`/`InPort`/`Param` attributes and an
execution context (`Periodic` or `OnInput`), override the `on_*` callbacks (sync or async).
Service ports (`ServiceProvider`/`ServiceConsumer` of an `Interface`, sdrpeer.sdk.services) call
named methods of another component, with timeouts and errors.
A port may declare its message type (`OutPort(type=Pose)`, a `@message` dataclass: the standard
robot types or your own, sdrpeer.sdk.typed); connecting two ports of different types is refused.
The host (`python -m sdrpeer.host`) wraps the instance in a `ComponentRunner`, which drives the
lifecycle of sdrpeer.sdk.lifecycle and reports every state change at once; the data plane
attaches sinks to OutPorts and delivers received frames to InPorts (docs/protocol.md). Faults a
component detects (`report_fault`) follow sdrpeer.sdk.faults; its working state moves to a new
instance through `on_snapshot`/`on_restore` (sdrpeer.sdk.handoff).
"""

from typing import TYPE_CHECKING, Any

from sdrpeer.sdk.component import Component
from sdrpeer.sdk.errors import (
    CallbackError,
    ComponentError,
    LifecycleError,
    NoData,
    ParamError,
    PortError,
)
from sdrpeer.sdk.execution import OnInput, Periodic, Stepped
from sdrpeer.sdk.faults import FAULT_EFFECTS, FAULT_KINDS, FaultEffect
from sdrpeer.sdk.handoff import HANDOFF_STATES
from sdrpeer.sdk.lifecycle import LifecycleState
from sdrpeer.sdk.params import Param, ParamInfo
from sdrpeer.sdk.policy import ConnectorPolicy
from sdrpeer.sdk.ports import FrameSink, InPort, InPortRuntime, OutPort, OutPortRuntime, PortInfo
from sdrpeer.sdk.runner import ComponentRunner
from sdrpeer.sdk.services import (
    Interface,
    ServiceCaller,
    ServiceCallError,
    ServiceConsumer,
    ServiceError,
    ServiceInfo,
    ServiceProvider,
    ServiceProviderRuntime,
    ServiceRequestError,
    ServiceTimeout,
    ServiceUnavailable,
)
from sdrpeer.sdk.typed import PortTypeError, message

if TYPE_CHECKING:  # loaded on first use (`__getattr__`): a host whose component uses none of
    # them does not pay for building their message types at start
    from sdrpeer.sdk.robot_types import BatteryState, Image, Odometry, Pose, RangeScan, Velocity

_ROBOT_TYPES = frozenset({"BatteryState", "Image", "Odometry", "Pose", "RangeScan", "Velocity"})


def __getattr__(name: str) -> Any:
    """The standard robot types (sdrpeer.sdk.robot_types), imported when first asked for."""
    if name in _ROBOT_TYPES:
        from sdrpeer.sdk import robot_types  # noqa: PLC0415 - lazy on purpose

        return getattr(robot_types, name)
    raise AttributeError(f"module 'sdrpeer.sdk' has no attribute {name!r}")


__all__ = [
    "FAULT_EFFECTS",
    "FAULT_KINDS",
    "HANDOFF_STATES",
    "BatteryState",
    "CallbackError",
    "Component",
    "ComponentError",
    "ComponentRunner",
    "ConnectorPolicy",
    "FaultEffect",
    "FrameSink",
    "Image",
    "InPort",
    "InPortRuntime",
    "Interface",
    "LifecycleError",
    "LifecycleState",
    "NoData",
    "Odometry",
    "OnInput",
    "OutPort",
    "OutPortRuntime",
    "Param",
    "ParamError",
    "ParamInfo",
    "Periodic",
    "PortError",
    "PortInfo",
    "PortTypeError",
    "Pose",
    "RangeScan",
    "ServiceCallError",
    "ServiceCaller",
    "ServiceConsumer",
    "ServiceError",
    "ServiceInfo",
    "ServiceProvider",
    "ServiceProviderRuntime",
    "ServiceRequestError",
    "ServiceTimeout",
    "ServiceUnavailable",
    "Stepped",
    "Velocity",
    "message",
]
