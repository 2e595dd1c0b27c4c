"""The errors the component SDK raises on purpose, one flat family under `SdrpeerError`.

How it works: each error names what was wrong and where (the param, the port, the callback, the
lifecycle state), so the host can forward the message to the agent unchanged.
"""

from __future__ import annotations

from sdrpeer.errors import SdrpeerError


class LifecycleError(SdrpeerError):
    """A lifecycle event was asked for in a state where it is not allowed."""

    def __init__(self, event: str, state: str, hint: str = "") -> None:
        message = f"cannot {event}: component is {state}"
        super().__init__(f"{message} ({hint})" if hint else message)
        self.event = event
        self.state = state


class CallbackError(SdrpeerError):
    """A component callback raised; `callback` names it and the cause is chained."""

    def __init__(self, callback: str, error: str) -> None:
        super().__init__(f"{callback} failed: {error}")
        self.callback = callback
        self.error = error


class ParamError(SdrpeerError):
    """A parameter value (or name) was rejected; `name` and `expected` say which and why."""

    def __init__(self, name: str, expected: str, got: object = None, *, detail: str = "") -> None:
        text = detail or f"expected {expected}, got {got!r}"
        super().__init__(f"param {name!r}: {text}")
        self.name = name
        self.expected = expected


class PortError(SdrpeerError):
    """A port was looked up by a name the component does not declare (or of the wrong kind)."""


class NoData(SdrpeerError):
    """An InPort was read before any frame arrived, or its queue is empty."""


class ComponentError(SdrpeerError):
    """A component class is declared wrongly (the message names the class and the attribute)."""
