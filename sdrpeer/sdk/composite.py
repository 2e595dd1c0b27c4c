"""Composite components: several members run as one component, in one shared, ordered context.

How it works: `composite_class(name, members, execution)` builds a `Composite` subclass (OpenRTM's
composite RTC with a PeriodicECShared context) out of member classes given in execution order.
To everything above the SDK it is one ordinary Component: `ComponentRunner` drives it, the host
serves it, the agent places, moves and restarts it as one instance. Its ports are the members'
runtime ports under `Member.port` and its params the members' params under `Member.param` (the
same objects: a member writing `self.out.write(v)` writes the composite's `Member.out`). Its
callbacks run the members' callbacks in order: initialize, startup, activate, execute, error and
reset in execution order; deactivate, shutdown and finalize in reverse. The composite's context
(`Periodic(hz=...)` or `Stepped()`) is the only one: members' own `execution` is ignored. A
member's failing callback raises `MemberError` naming the member, so the runner moves the whole
composite to ERROR with that text; an activation that fails part-way deactivates the members
already activated (reverse order) first. A member's fault is reported by the composite with the
member's name before its detail. `on_snapshot` returns `{member: state}` for every member whose
state is not None (None when none has one); `on_restore` checks the whole map before it hands
each member its part.
"""

from __future__ import annotations

import copy
import functools
import inspect
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any, ClassVar

from sdrpeer.sdk.component import Component
from sdrpeer.sdk.errors import ComponentError, ParamError
from sdrpeer.sdk.execution import Periodic, Stepped
from sdrpeer.sdk.params import Param
from sdrpeer.sdk.ports import InPort, OutPort

__all__ = ["Composite", "MemberError", "composite_class"]


class MemberError(Exception):
    """A member's callback raised; the text names the member, the callback and the cause."""

    def __init__(self, member: str, callback: str, exc: BaseException) -> None:
        super().__init__(f"member {member}: {callback}: {type(exc).__name__}: {exc}")
        self.member = member
        self.callback = callback


class _MemberValues(dict[str, Any]):
    """The composite's param values (`Member.param`), written through to the members' own."""

    def __init__(self, members: Mapping[str, Component]) -> None:
        super().__init__(
            {f"{m}.{k}": v for m, c in members.items() for k, v in c._param_values.items()}
        )
        self._members = members

    def __setitem__(self, key: str, value: Any) -> None:
        super().__setitem__(key, value)
        member, _, param = key.partition(".")
        self._members[member]._param_values[param] = value

    def update(self, other: Any = (), /, **more: Any) -> None:
        """Set every item through `__setitem__` (dict.update would skip the members)."""
        for key, value in dict(other, **more).items():
            self[key] = value


class Composite(Component):
    """Several member components run as one, in the order of `members` (see the module doc)."""

    members: ClassVar[tuple[tuple[str, type[Component]], ...]] = ()
    """(member name, class) in execution order."""

    def __init__(self, name: str | None = None, params: Mapping[str, Any] | None = None) -> None:
        cls = type(self)
        own = name or cls.__name__
        given: dict[str, dict[str, Any]] = {m: {} for m, _ in cls.members}
        for key, value in (params or {}).items():
            member, _, param = key.partition(".")
            if key not in cls._sdk_params:
                known = ", ".join(cls._sdk_params) or "none"
                raise ParamError(key, "Member.param", detail=f"unknown param (known: {known})")
            given[member][param] = value
        self.parts: dict[str, Component] = {
            m: mcls(name=f"{own}.{m}", params=given[m]) for m, mcls in cls.members
        }
        """The member instances by name, in execution order."""
        super().__init__(own)
        self._ports = {
            f"{m}.{p}": port for m, c in self.parts.items() for p, port in c._ports.items()
        }
        self._param_values = _MemberValues(self.parts)
        for m, c in self.parts.items():
            c._fault_hook = functools.partial(self._member_fault, m)
        self._initialized: set[str] = set()
        self._started: set[str] = set()

    def param_values(self) -> dict[str, Any]:
        """The current value of every member's param, as `Member.param` (a copy)."""
        return {f"{m}.{k}": v for m, c in self.parts.items() for k, v in c._param_values.items()}

    def member_errors(self) -> dict[str, str | None]:
        """Each member's last error (None: none), in execution order."""
        return {m: c.last_error for m, c in self.parts.items()}

    def _member_fault(self, member: str, kind: str, detail: str) -> None:
        self.report_fault(kind, f"{member}: {detail}" if detail else member)

    # -- running the members' callbacks ----------------------------------------------------

    def _order(self, reverse: bool = False) -> list[tuple[str, Component]]:
        items = list(self.parts.items())
        return items[::-1] if reverse else items

    async def _call(self, member: str, comp: Component, callback: str, *args: Any) -> None:
        """One member's callback; MemberError (and the member's last_error set) if it raises."""
        await _member_call(member, comp, callback, getattr(comp, callback), *args)

    async def _each(self, callback: str, members: Iterable[tuple[str, Component]]) -> None:
        """Call `callback` on every member given, in order, stopping at the first failure."""
        for m, c in members:
            await self._call(m, c, callback)

    async def _all(self, callback: str, members: Iterable[tuple[str, Component]]) -> None:
        """Call `callback` on every member given even if some fail; raise the first failure."""
        first: MemberError | None = None
        for m, c in members:
            try:
                await self._call(m, c, callback)
            except MemberError as exc:
                self.log.error("%s", exc)
                first = first or exc
        if first is not None:
            raise first

    async def on_initialize(self) -> None:
        """Each member's on_initialize in order (one that already succeeded is not repeated)."""
        for m, c in self._order():
            if m not in self._initialized:
                await self._call(m, c, "on_initialize")
                self._initialized.add(m)

    async def on_startup(self) -> None:
        """Each member's on_startup in order (not repeated after a reset)."""
        for m, c in self._order():
            if m not in self._started:
                await self._call(m, c, "on_startup")
                self._started.add(m)

    async def on_activated(self) -> None:
        """Each member's on_activated in order; if one fails, those already activated are
        deactivated again (reverse order) before the failure is raised."""
        done: list[tuple[str, Component]] = []
        for m, c in self._order():
            try:
                await self._call(m, c, "on_activated")
            except MemberError:
                for dm, dc in reversed(done):
                    try:
                        await self._call(dm, dc, "on_deactivated")
                    except MemberError as undo:
                        self.log.error("undoing the activation: %s", undo)
                raise
            done.append((m, c))

    async def on_execute(self) -> None:
        """Each member's on_execute in order (one with none is skipped)."""
        for m, c in self._order():
            if type(c).on_execute is not Component.on_execute:
                await self._call(m, c, "on_execute")

    async def on_deactivated(self) -> None:
        """Each member's on_deactivated in reverse order."""
        await self._all("on_deactivated", self._order(reverse=True))

    async def on_aborting(self) -> None:
        """Each member's on_aborting in reverse order (all of them: each makes its part safe)."""
        await self._all("on_aborting", self._order(reverse=True))

    async def on_error(self) -> None:
        """Each member's on_error in order."""
        await self._all("on_error", self._order())

    async def on_reset(self) -> None:
        """Each member's on_reset in order."""
        await self._each("on_reset", self._order())

    async def on_shutdown(self) -> None:
        """Each started member's on_shutdown in reverse order."""
        await self._all("on_shutdown", [i for i in self._order(True) if i[0] in self._started])

    async def on_finalize(self) -> None:
        """Each member's on_finalize in reverse order."""
        await self._all("on_finalize", self._order(reverse=True))

    async def on_params_changed(self, changed: dict[str, Any]) -> None:
        """Hand each member its changed params: their `on_change` hooks, then its
        `on_params_changed`, member by member in order."""
        for m, c in self._order():
            mine = {k.partition(".")[2]: v for k, v in changed.items() if k.startswith(f"{m}.")}
            if not mine:
                continue
            declared = type(c)._sdk_params
            for param, value in mine.items():
                hook = declared[param].on_change
                if hook is None:
                    continue
                fn: Callable[..., Any] = (
                    getattr(c, hook) if isinstance(hook, str) else functools.partial(hook, c)
                )
                await _member_call(m, c, f"{param}.on_change", fn, value)
            await self._call(m, c, "on_params_changed", mine)

    # -- state handoff ---------------------------------------------------------------------

    async def on_snapshot(self) -> dict[str, Any] | None:
        """`{member: state}` of every member whose `on_snapshot` gives one; None if none does."""
        states: dict[str, Any] = {}
        for m, c in self._order():
            if type(c).on_snapshot is Component.on_snapshot:
                continue
            try:
                result = c.on_snapshot()
                state = (await result) if inspect.isawaitable(result) else result
            except Exception as exc:
                raise MemberError(m, "on_snapshot", exc) from exc
            if state is not None:
                states[m] = state
        return states or None

    async def on_restore(self, state: Any) -> None:
        """Hand each member its part of a `{member: state}` map (checked whole first)."""
        if state is None:
            return
        if not isinstance(state, Mapping):
            raise ValueError(f"expected a map of member states, got {type(state).__name__}")
        for m, part in state.items():
            comp = self.parts.get(m) if isinstance(m, str) else None
            if comp is None:
                raise ValueError(f"no member {m!r} (members: {', '.join(self.parts)})")
            if part is not None and type(comp).on_restore is Component.on_restore:
                raise ValueError(f"member {m} has no on_restore: it takes no state")
        for m, c in self._order():
            if m in state:
                await self._call(m, c, "on_restore", state[m])


async def _member_call(
    member: str, comp: Component, name: str, fn: Callable[..., Any], *args: Any
) -> None:
    """Run one of a member's callbacks; MemberError (the member's last_error set) if it raises."""
    try:
        result = fn(*args)
        if inspect.isawaitable(result):
            await result
    except Exception as exc:
        error = MemberError(member, name, exc)
        comp.last_error = str(error)
        raise error from exc


def composite_class(
    name: str,
    members: Sequence[tuple[str, type[Component]]],
    execution: Periodic | Stepped,
) -> type[Composite]:
    """A Composite subclass called `name` running `members` (name, class) in this order under
    `execution` (a fixed-rate `Periodic` or `Stepped`); ComponentError if they do not fit."""
    if not members:
        raise ComponentError(f"composite {name}: it has no members")
    if isinstance(execution, Periodic) and execution.hz is None:
        raise ComponentError(f"composite {name}: its Periodic context needs a fixed hz")
    if not isinstance(execution, Periodic | Stepped):
        raise ComponentError(f"composite {name}: expected Periodic(hz=...) or Stepped()")
    seen: set[str] = set()
    for member, mcls in members:
        if not member.isidentifier():
            raise ComponentError(f"composite {name}: member name {member!r} is not an identifier")
        if member in seen:
            raise ComponentError(f"composite {name}: member {member!r} given twice")
        if not (isinstance(mcls, type) and issubclass(mcls, Component)):
            raise ComponentError(f"composite {name}: member {member}: not a Component class")
        if issubclass(mcls, Composite):
            raise ComponentError(f"composite {name}: member {member}: composites do not nest")
        if mcls._sdk_services:
            raise ComponentError(
                f"composite {name}: member {member}: declares service ports "
                f"({', '.join(mcls._sdk_services)}), which a composite does not carry yet: "
                "run it as a component of its own"
            )
        seen.add(member)
    cls: type[Composite] = type(
        name, (Composite,), {"execution": execution, "members": tuple(members)}
    )
    ports: dict[str, InPort | OutPort] = {}
    params: dict[str, Param[Any]] = {}
    for member, mcls in members:
        for port, decl in mcls._sdk_ports.items():
            ports[f"{member}.{port}"] = decl
        for pname, param in mcls._sdk_params.items():
            mine = copy.copy(param)
            mine.name, mine.on_change = f"{member}.{pname}", None  # the member runs its hooks
            params[mine.name] = mine
            setattr(cls, mine.name, mine)
    cls._sdk_ports = ports
    cls._sdk_params = params
    return cls
