"""A named set of plugins (launchers, allocation strategies and constraints, recovery conditions
and actions) backed by an entry point group: the one plugin registry.

How it works: a `Registry` reads its entry point group once, on the first lookup, and keeps the
loaded objects. `get(name)` returns an instance: an entry point naming a class is instantiated
with no arguments, anything else is used as is. `register(name, obj)` adds or replaces a plugin
in this process (tests, embedding applications) and wins over an entry point of the same name;
`unregister(name)` takes it back out (built-in plugins are registered, so they win over entry
points of their name). An unknown name raises `error` (a `ConfigError`) listing the known ones: it
comes from a system file's `allocation:` or `recovery:` section, or an instance's launcher, which
`label` names in messages.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Generic, TypeVar

from sdrpeer.errors import ConfigError

T = TypeVar("T")


class Registry(Generic[T]):
    """Plugins of one kind, by name: entry points of `group`, plus any registered in-process."""

    def __init__(
        self,
        group: str,
        kinds: tuple[type[Any], ...],
        label: str,
        *,
        error: type[ConfigError] = ConfigError,
    ) -> None:
        self.group = group
        """The entry point group read on first use."""
        self.kinds = kinds
        """Every plugin must be an instance of one of these classes (T's members)."""
        self.label = label
        """How messages call a plugin of this kind (e.g. 'allocation constraint', 'launcher')."""
        self.error = error
        """What an unknown, broken or wrong plugin raises."""
        self._entry_points: dict[str, Any] | None = None
        self._loaded: dict[str, T] = {}
        self._registered: dict[str, T] = {}

    def _points(self) -> dict[str, Any]:
        """The group's entry points by name (read once)."""
        if self._entry_points is None:
            from importlib.metadata import entry_points  # noqa: PLC0415 - only when needed

            self._entry_points = {ep.name: ep for ep in entry_points(group=self.group)}
        return self._entry_points

    def names(self) -> list[str]:
        """Every plugin name available, sorted."""
        return sorted(set(self._points()) | set(self._registered))

    def register(self, name: str, plugin: T | Callable[[], T]) -> None:
        """Add (or replace) a plugin in this process; a class is instantiated with no arguments."""
        self._registered[name] = self._check(name, plugin() if isinstance(plugin, type) else plugin)

    def unregister(self, name: str) -> None:
        """Remove a plugin added with `register` (entry points stay)."""
        self._registered.pop(name, None)

    def get(self, name: str) -> T:
        """The plugin called `name`; ConfigError naming the known ones when there is none."""
        found = self._registered.get(name) or self._loaded.get(name)
        if found is not None:
            return found
        ep = self._points().get(name)
        if ep is None:
            known = ", ".join(self.names())
            raise self.error(f"unknown {self.label} {name!r} (known: {known})")
        try:
            obj = ep.load()
            plugin = obj() if isinstance(obj, type) else obj
        except Exception as exc:
            raise self.error(f"{self.label} {name!r} ({ep.value}) failed to load: {exc}") from exc
        self._loaded[name] = self._check(name, plugin)
        return self._loaded[name]

    def _check(self, name: str, plugin: object) -> T:
        """The plugin, if it is of the right kind."""
        if not isinstance(plugin, self.kinds):
            wanted = " or ".join(k.__name__ for k in self.kinds)
            raise self.error(f"{self.label} {name!r} is a {type(plugin).__name__}, not a {wanted}")
        return plugin  # type: ignore[no-any-return]
