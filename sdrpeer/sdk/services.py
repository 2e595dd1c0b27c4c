"""Service ports: named methods one component provides and another calls (request and reply).

How it works: an `Interface` is a name and method names, each method optionally with a request
and a reply `@message` type (sdrpeer.sdk.typed). Its *interface id*, `name#digest`, covers the
methods and their types, so two programs that disagree about an interface are told apart (the
provider's host refuses a consumer whose id differs, and so does `sdrpeer system check`).

- `ServiceProvider(interface)` on a Component class is served by the class's methods marked
  `@port.method` (or `@port.method("name")`); every method of the interface must be implemented,
  checked when the class is created. Each instance gets a `ServiceProviderRuntime`, which the
  host's data server hands every request to: it is answered only while the component is ACTIVE
  (else an error reply of kind `ServiceUnavailable`), a sync handler runs inline on the host's
  loop, an async one as a task, and a handler that raises is answered with its exception's type
  name and message: the component keeps running.
- `ServiceConsumer(interface)` gives each instance a `ServiceCaller`: ``await
  self.planner.call("compute", goal, timeout=0.5)`` (or ``self.planner.compute(goal)``). The
  host binds it to a link (sdrpeer.dataplane.service) when the agent connects the binding.
  Every failure is a `ServiceCallError`: `ServiceError` (the provider's handler raised: its
  `kind` and `message`), `ServiceTimeout` (no reply in time; the call may still run on the
  provider), `ServiceUnavailable` (not bound, the provider unreachable or not ACTIVE, or the
  link lost or re-pointed while the call was in flight: it is not retried, since the provider
  may have run it), `ServiceRequestError` (the call's argument cannot be encoded or its request
  is over the maximum frame: nothing was sent).
"""

from __future__ import annotations

import asyncio
import inspect
import logging
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, ClassVar, Final, Literal, Protocol, TypeVar, overload

from sdrpeer.errors import MalformedError, SdrpeerError
from sdrpeer.sdk.errors import ComponentError, PortError
from sdrpeer.sdk.typed import PortTypeError, port_message
from sdrpeer.vocabulary import LifecycleState

try:  # the C module itself: `hashlib` would load OpenSSL into every host (sdrpeer.host.lean)
    from _blake2 import blake2b
except ImportError:  # pragma: no cover - an interpreter without it
    from hashlib import blake2b

__all__ = [
    "CallLink",
    "Interface",
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
]

log = logging.getLogger("sdrpeer.sdk.services")
F = TypeVar("F", bound=Callable[..., Any])
Reply = Callable[[int, bool, Any], None]
"""Answers one call: (call id, ok, the reply value or ``[error kind, message]``)."""
UNAVAILABLE: Final = "ServiceUnavailable"
"""The error kind a provider answers with while it is not ACTIVE."""
DEFAULT_TIMEOUT: Final = 1.0
"""Seconds a call waits for its reply when the caller gives no timeout."""
_MARK: Final = "__sdr_service__"


class ServiceCallError(SdrpeerError):
    """A service call failed; the subclasses say how."""


class ServiceError(ServiceCallError):
    """The provider's handler raised: `kind` is its exception's type name, `message` its text."""

    def __init__(self, method: str, kind: str, message: str) -> None:
        super().__init__(f"{method}: {kind}: {message}")
        self.method = method
        self.kind = kind
        self.message = message


class ServiceRequestError(ServiceCallError):
    """The request was not sent: its argument cannot be encoded, or it is over the maximum frame."""


class ServiceTimeout(ServiceCallError):
    """No reply within the call's timeout (the provider may still run the call)."""


class ServiceUnavailable(ServiceCallError):
    """Not bound, provider unreachable or not ACTIVE, or the link went away during the call."""


@dataclass(frozen=True, slots=True)
class Interface:
    """A service interface: a name and its methods, each with optional message types."""

    name: str
    """E.g. ``"demo/Planner"`` (1-100 characters, no spaces or '#')."""
    methods: tuple[str, ...]
    """The method names, in declaration order."""
    types: tuple[tuple[str, type | None, type | None], ...] = ()
    """(method, request type, reply type) for the typed methods (`@message` dataclasses)."""

    @classmethod
    def of(
        cls,
        name: str,
        *methods: str,
        types: Mapping[str, tuple[type | None, type | None]] | None = None,
    ) -> Interface:
        """``Interface.of("demo/Planner", "compute", "status", types={"compute": (Goal, Path)})``;
        ValueError or TypeError when a name or a type is wrong."""
        if not name or len(name) > 100 or any(c.isspace() or c == "#" for c in name):
            raise ValueError(f"interface name {name!r}: 1-100 characters, no spaces or '#'")
        if not methods:
            raise ValueError(f"interface {name!r}: no methods")
        for m in methods:
            if not m.isidentifier() or m.startswith("_"):
                raise ValueError(f"interface {name!r}: method {m!r} is not a public identifier")
        if len(set(methods)) != len(methods):
            raise ValueError(f"interface {name!r}: a method is named twice")
        typed = []
        for method, (request, reply) in (types or {}).items():
            if method not in methods:
                raise ValueError(f"interface {name!r}: types for unknown method {method!r}")
            port_message(request)  # TypeError unless None or a @message dataclass
            port_message(reply)
            typed.append((method, request, reply))
        return cls(name, tuple(methods), tuple(typed))

    @property
    def id(self) -> str:
        """``name#digest``: BLAKE2b (4 bytes) over ``name(method:request>reply;...)``, the
        methods sorted, each type its type id or ``any``."""
        kinds = {m: (_tid(q), _tid(r)) for m, q, r in self.types}
        untyped = ("any", "any")
        layout = ";".join(f"{m}:{'>'.join(kinds.get(m, untyped))}" for m in sorted(self.methods))
        digest = blake2b(f"{self.name}({layout})".encode(), digest_size=4).hexdigest()
        return f"{self.name}#{digest}"

    def request_type(self, method: str) -> type | None:
        """The request's message type of `method`, None when untyped."""
        return next((q for m, q, _ in self.types if m == method), None)

    def reply_type(self, method: str) -> type | None:
        """The reply's message type of `method`, None when untyped."""
        return next((r for m, _, r in self.types if m == method), None)


def _tid(t: type | None) -> str:
    info = port_message(t)
    return "any" if info is None else info.type_id


def _encode(t: type | None, value: Any, what: str) -> Any:
    info = port_message(t)
    if info is None:
        return value
    if not isinstance(value, info.cls):
        raise PortTypeError(f"{what}: expected a {info.type_id}, got {type(value).__name__}")
    return info.flat(value)


def _decode(t: type | None, wire: Any) -> Any:
    info = port_message(t)
    return wire if info is None else info.decode(wire)


@dataclass(frozen=True, slots=True)
class ServiceInfo:
    """What the host reports about one declared service port (the `hello`'s `services`)."""

    name: str
    """The attribute name, used as the port's name in connections."""
    role: Literal["provides", "requires"]
    """A provider or a consumer."""
    interface: str
    """The interface id."""
    methods: tuple[str, ...]
    """The interface's method names."""

    def to_map(self) -> dict[str, Any]:
        """A msgpack/JSON-friendly map."""
        return {"role": self.role, "interface": self.interface, "methods": list(self.methods)}


# -- the provider ---------------------------------------------------------------------------


class ServiceProviderRuntime:
    """One instance's provided service: answers the requests its data server hands it."""

    def __init__(
        self, name: str, interface: Interface, handlers: Mapping[str, Callable[..., Any]]
    ) -> None:
        self.name = name
        self.interface = interface
        self.interface_id = interface.id
        """What a consumer's hello must name."""
        self.handlers = dict(handlers)
        self.serving = False
        """True while the component is ACTIVE (the host sets it): calls are served only then."""
        self.state: str = LifecycleState.CREATED
        """The component's lifecycle state, for the error reply while not serving."""
        self.calls = 0
        """Requests answered (ok or not)."""
        self.failed = 0
        """Requests answered with an error."""
        self._tasks: set[asyncio.Task[None]] = set()
        self._logged: set[tuple[str, str]] = set()  # (method, error kind) already warned about

    @property
    def running(self) -> int:
        """Calls whose async handler has not finished yet."""
        return len(self._tasks)

    def counters(self) -> dict[str, int]:
        """For heartbeats: calls answered, and of those with an error."""
        return {"calls": self.calls, "failed": self.failed}

    def serve(self, call_id: int, method: str, arg: Any, reply: Reply) -> None:
        """Answer one request through `reply` (now, or when an async handler finishes)."""
        if not self.serving:
            self._fail(reply, call_id, UNAVAILABLE, f"{self.name} is not ACTIVE ({self.state})")
            return
        handler = self.handlers.get(method)
        if handler is None:
            known = ", ".join(self.interface.methods)
            self._fail(reply, call_id, "UnknownMethod", f"no method {method!r} (have: {known})")
            return
        try:
            result = handler(_decode(self.interface.request_type(method), arg))
        except Exception as exc:
            self._raised(reply, call_id, method, exc)
            return
        if inspect.isawaitable(result):
            task = asyncio.ensure_future(self._finish(call_id, method, result, reply))
            self._tasks.add(task)
            task.add_done_callback(self._tasks.discard)
            return
        self._answer(reply, call_id, method, result)

    async def _finish(self, call_id: int, method: str, result: Any, reply: Reply) -> None:
        try:
            value = await result
        except Exception as exc:
            self._raised(reply, call_id, method, exc)
            return
        self._answer(reply, call_id, method, value)

    def _answer(self, reply: Reply, call_id: int, method: str, value: Any) -> None:
        try:
            wire = _encode(self.interface.reply_type(method), value, f"{self.name}.{method} reply")
        except PortTypeError as exc:
            self._raised(reply, call_id, method, exc)
            return
        self.calls += 1
        reply(call_id, True, wire)

    def _raised(self, reply: Reply, call_id: int, method: str, exc: Exception) -> None:
        kind = type(exc).__name__
        first = (method, kind) not in self._logged  # a warning the first time, then debug
        self._logged.add((method, kind))
        log.log(
            logging.WARNING if first else logging.DEBUG,
            "%s.%s raised %s: %s",
            self.name,
            method,
            kind,
            exc,
        )
        self._fail(reply, call_id, kind, str(exc))

    def _fail(self, reply: Reply, call_id: int, kind: str, message: str) -> None:
        self.calls += 1
        self.failed += 1
        reply(call_id, False, [kind, message])

    def cancel(self) -> None:
        """Cancel the async handlers still running (the host is stopping)."""
        for task in list(self._tasks):
            task.cancel()


class _ServicePort:
    """What the two declarations of a service port share: the interface, a doc, the name."""

    role: ClassVar[str]

    def __init__(self, interface: Interface, doc: str = "") -> None:
        if not isinstance(interface, Interface):
            raise TypeError(f"{type(self).__name__} needs an Interface, got {interface!r}")
        self.interface = interface
        self.doc = doc
        self.name = "<unbound>"

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name


class ServiceProvider(_ServicePort):
    """Declare a provided service on a Component class; mark its handlers with `method`."""

    role = "provides"

    @overload
    def method(self, fn_or_name: F) -> F: ...
    @overload
    def method(self, fn_or_name: str) -> Callable[[F], F]: ...
    def method(self, fn_or_name: Any) -> Any:
        """Mark a Component method as the handler of the interface method of the same name
        (``@planner.method``) or of the one named (``@planner.method("compute")``)."""
        if isinstance(fn_or_name, str):
            name = fn_or_name

            def mark(fn: F) -> F:
                setattr(fn, _MARK, (self, name))
                return fn

            return mark
        setattr(fn_or_name, _MARK, (self, fn_or_name.__name__))
        return fn_or_name

    def handlers(self, cls: type) -> dict[str, str]:
        """Interface method -> the attribute of `cls` that handles it; ComponentError when one
        is missing, named twice, or not in the interface."""
        where = f"{cls.__qualname__}.{self.name}"
        found: dict[str, str] = {}
        for klass in reversed(cls.__mro__):
            here: set[str] = set()  # methods handled in this class (a subclass may override)
            for attr, value in vars(klass).items():
                mark = getattr(value, _MARK, None)
                if not isinstance(mark, tuple) or mark[0] is not self:
                    continue
                method = mark[1]
                if method not in self.interface.methods:
                    known = ", ".join(self.interface.methods)
                    raise ComponentError(
                        f"{where}: {attr} handles {method!r}, not a method of "
                        f"{self.interface.name} ({known})"
                    )
                if method in here:
                    raise ComponentError(f"{where}: {method!r} handled twice ({attr})")
                here.add(method)
                found[method] = attr
        missing = [m for m in self.interface.methods if m not in found]
        if missing:
            raise ComponentError(
                f"{where}: no handler for {', '.join(missing)} (mark one with @{self.name}.method)"
            )
        return found

    @overload
    def __get__(self, instance: None, owner: type | None = None) -> ServiceProvider: ...
    @overload
    def __get__(self, instance: object, owner: type | None = None) -> ServiceProviderRuntime: ...
    def __get__(self, instance: object | None, owner: type | None = None) -> Any:
        if instance is None:
            return self
        return instance._services[self.name]  # type: ignore[attr-defined]

    def make(self, component: Any, handlers: Mapping[str, str]) -> ServiceProviderRuntime:
        """The runtime port of one instance, its handlers bound to `component`."""
        bound = {m: getattr(component, attr) for m, attr in handlers.items()}
        return ServiceProviderRuntime(self.name, self.interface, bound)

    def info(self) -> ServiceInfo:
        """This port's metadata."""
        return ServiceInfo(self.name, "provides", self.interface.id, self.interface.methods)


# -- the consumer ---------------------------------------------------------------------------


class CallLink(Protocol):
    """Where a `ServiceCaller` sends its calls (sdrpeer.dataplane.service's `ServiceClient`)."""

    async def request(self, method: str, arg: Any) -> tuple[bool, Any]:
        """(ok, the reply value or ``[kind, message]``); ConnectionError when the provider
        cannot be reached or the link was lost or re-pointed before the reply."""
        ...


class ServiceCaller:
    """One instance's required service: ``await caller.call("method", arg, timeout=0.5)``."""

    def __init__(self, name: str, interface: Interface) -> None:
        self.name = name
        self.interface = interface
        self.link: CallLink | None = None
        """Set by the host while the binding is connected."""
        self.calls = 0
        """Calls made."""
        self.failed = 0
        """Calls that raised a ServiceCallError."""
        self.timeouts = 0
        """Of those, ServiceTimeout."""
        self.unavailable = 0
        """Of those, ServiceUnavailable (the rest are the provider's ServiceError)."""

    def counters(self) -> dict[str, int]:
        """For heartbeats: calls, failed, and of those timeouts and unavailable."""
        return {
            "calls": self.calls,
            "failed": self.failed,
            "timeouts": self.timeouts,
            "unavailable": self.unavailable,
        }

    def bind(self, link: CallLink | None) -> None:
        """Send calls through `link` (None: unbound, calls fail with ServiceUnavailable)."""
        self.link = link

    async def call(
        self,
        method: str,
        arg: Any = None,
        *,
        timeout: float = DEFAULT_TIMEOUT,  # noqa: ASYNC109 - a call's deadline is its contract
    ) -> Any:
        """Call `method` with `arg`; its reply value (decoded when the interface types it).
        PortError for a method the interface does not have; ServiceCallError subclasses when
        the call fails (see the module doc)."""
        if method not in self.interface.methods:
            known = ", ".join(self.interface.methods)
            iface = self.interface.name
            raise PortError(f"{self.name}: {iface} has no method {method!r} ({known})")
        wire = _encode(self.interface.request_type(method), arg, f"{self.name}.{method}")
        self.calls += 1
        try:
            value = await self._call(method, wire, timeout)
            return _decode(self.interface.reply_type(method), value)
        except ServiceCallError as exc:
            self.failed += 1
            self.timeouts += isinstance(exc, ServiceTimeout)
            self.unavailable += isinstance(exc, ServiceUnavailable)
            raise

    async def _call(self, method: str, wire: Any, timeout: float) -> Any:  # noqa: ASYNC109
        link = self.link
        if link is None:
            raise ServiceUnavailable(f"{self.name}: not connected to a provider")
        try:
            async with asyncio.timeout(timeout):
                ok, value = await link.request(method, wire)
        except TimeoutError:
            raise ServiceTimeout(f"{self.name}.{method}: no reply within {timeout:g} s") from None
        except (ConnectionError, OSError) as exc:
            raise ServiceUnavailable(f"{self.name}.{method}: {exc}") from None
        except MalformedError as exc:  # the data plane's FrameError: nothing was sent
            raise ServiceRequestError(f"{self.name}.{method}: {exc}") from None
        if ok:
            return value
        kind, message = _error(value)
        if kind == UNAVAILABLE:
            raise ServiceUnavailable(f"{self.name}.{method}: {message}")
        raise ServiceError(method, kind, message)

    def __getattr__(self, name: str) -> Callable[..., Any]:
        """``caller.compute(arg, timeout=...)`` is ``caller.call("compute", arg, ...)``."""
        if name.startswith("_") or name not in self.interface.methods:
            raise AttributeError(name)

        async def method(arg: Any = None, *, timeout: float = DEFAULT_TIMEOUT) -> Any:  # noqa: ASYNC109
            return await self.call(name, arg, timeout=timeout)

        return method


def _error(value: Any) -> tuple[str, str]:
    """(kind, message) of an error reply (anything malformed is a ProtocolError)."""
    if type(value) is list and len(value) == 2 and all(isinstance(x, str) for x in value):
        return value[0], value[1]
    return "ProtocolError", f"malformed error reply {value!r:.60}"


class ServiceConsumer(_ServicePort):
    """Declare a required service on a Component class."""

    role = "requires"

    @overload
    def __get__(self, instance: None, owner: type | None = None) -> ServiceConsumer: ...
    @overload
    def __get__(self, instance: object, owner: type | None = None) -> ServiceCaller: ...
    def __get__(self, instance: object | None, owner: type | None = None) -> Any:
        if instance is None:
            return self
        return instance._services[self.name]  # type: ignore[attr-defined]

    def make(self) -> ServiceCaller:
        """The runtime port of one instance."""
        return ServiceCaller(self.name, self.interface)

    def info(self) -> ServiceInfo:
        """This port's metadata."""
        return ServiceInfo(self.name, "requires", self.interface.id, self.interface.methods)
