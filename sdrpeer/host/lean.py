"""A host starts without OpenSSL unless its component needs it.

How it works: asyncio imports `ssl` at import time only in case a loop is later asked for TLS
(`try: import ssl except ImportError: ssl = None` in base_events, selector_events and sslproto).
Loading ssl maps and initialises libcrypto and libssl, about 4.5 MiB of every host's RSS, while
almost no component speaks TLS. `import_asyncio()` imports asyncio with `ssl` hidden (asyncio takes
it as absent) and puts a finder first on `sys.meta_path` that watches for the first real
`import ssl` — from the component's module, a library it uses, or a function called much later.
That import proceeds as usual and, once the module has run, asyncio is given it (the three
modules' `ssl` names and sslproto's `SSLAgainErrors`, exactly what their own import would have
set), so TLS through the host's loop works as it always does. Call it before anything imports
asyncio; if asyncio or ssl is already imported, it does nothing.
"""

from __future__ import annotations

import importlib.abc
import importlib.machinery
import sys
from collections.abc import Sequence
from types import ModuleType

__all__ = ["give_asyncio_ssl", "import_asyncio"]

_ASYNCIO_USERS = ("asyncio.base_events", "asyncio.selector_events", "asyncio.sslproto")


def import_asyncio() -> None:
    """Import asyncio without loading ssl; ssl is handed to asyncio when something imports it."""
    if "asyncio" in sys.modules or "ssl" in sys.modules:
        return
    sys.modules["ssl"] = None  # type: ignore[assignment]  # the documented "not importable" mark
    try:
        import asyncio  # noqa: F401, PLC0415
    finally:
        del sys.modules["ssl"]
    sys.meta_path.insert(0, _SslWatcher())


def give_asyncio_ssl(ssl: ModuleType) -> None:
    """Set what asyncio's modules would have set had ssl been importable when they were."""
    for name in _ASYNCIO_USERS:
        module = sys.modules.get(name)
        if module is not None and getattr(module, "ssl", None) is None:
            module.ssl = ssl  # type: ignore[attr-defined]
    sslproto = sys.modules.get("asyncio.sslproto")
    if sslproto is not None and not hasattr(sslproto, "SSLAgainErrors"):
        sslproto.SSLAgainErrors = (ssl.SSLWantReadError, ssl.SSLSyscallError)  # type: ignore[attr-defined]


class _SslWatcher(importlib.abc.MetaPathFinder):
    """Finds nothing itself: wraps the real loader of `ssl` so asyncio gets the module."""

    def find_spec(
        self, fullname: str, path: Sequence[str] | None, target: ModuleType | None = None
    ) -> importlib.machinery.ModuleSpec | None:
        if fullname != "ssl":
            return None
        sys.meta_path.remove(self)  # once: the real finders answer from here on
        spec = importlib.machinery.PathFinder.find_spec(fullname, path)
        if spec is not None and spec.loader is not None:
            spec.loader = _ThenGive(spec.loader)
        return spec


class _ThenGive(importlib.abc.Loader):
    """The real loader of ssl, then `give_asyncio_ssl`."""

    def __init__(self, loader: importlib.abc.Loader) -> None:
        self.loader = loader

    def create_module(self, spec: importlib.machinery.ModuleSpec) -> ModuleType | None:
        return self.loader.create_module(spec)

    def exec_module(self, module: ModuleType) -> None:
        self.loader.exec_module(module)
        give_asyncio_ssl(module)

    def __getattr__(self, name: str) -> object:  # get_source, get_filename, ... (tracebacks)
        return getattr(self.loader, name)
