"""Find the Component class a host runs, from `pkg.mod:Class` or `path/to/file.py[:Class]`.

How it works: `split_target` cuts an optional `:Name` off the end (only when what follows the last
colon is an identifier). A target naming a file (it ends in `.py` or contains a `/`) is executed as
a fresh module named after the file, with the file's directory first on `sys.path` as
`python file.py` would do; anything else is imported as a module. The class is then looked up by
name or, without a name, is the single subclass of `base` defined in that module (not merely
imported into it). `load_composite_class` reads a composite's target (sdrpeer.launch.composite),
loads each member's class that way and builds the composite (sdrpeer.sdk.composite). Every
failure is a `LoadError` whose message names the target and what was wrong; when user code
raised, the exception is chained so the caller can show its traceback.
"""

from __future__ import annotations

import importlib
import importlib.util
import inspect
import os
import sys
from types import ModuleType

from sdrpeer.errors import LoadError, SdrpeerError
from sdrpeer.launch.composite import parse_composite


def split_target(target: str) -> tuple[str, str | None]:
    """Split `where[:Name]` into (where, Name or None)."""
    where, sep, name = target.rpartition(":")
    if sep and where and name.isidentifier():
        return where, name
    return target, None


def is_file_target(where: str) -> bool:
    """True if `where` names a Python file rather than a module."""
    return where.endswith(".py") or os.sep in where


def load_component_class(target: str, base: type | tuple[type, ...]) -> type:
    """Import `target` and return the subclass of `base` (or of one of several bases) it
    names."""
    where, name = split_target(target)
    module = _load_file(target, where) if is_file_target(where) else _load_module(target, where)
    if name is None:
        return _single_subclass(target, module, base)
    cls = getattr(module, name, None)
    if cls is None:
        raise LoadError(f"{target}: {where} defines no {name!r}")
    if not (inspect.isclass(cls) and issubclass(cls, base)) or cls in _bases(base):
        raise LoadError(f"{target}: {name} is not a subclass of {_names(base)}")
    return cls


def load_composite_class(name: str, target: str) -> type:
    """The composite class called `name` that a composite target describes (LoadError if a
    member cannot be loaded or the members do not fit together)."""
    from sdrpeer.sdk import Component  # noqa: PLC0415 - only hosts need the SDK
    from sdrpeer.sdk.composite import composite_class  # noqa: PLC0415
    from sdrpeer.sdk.execution import Periodic, Stepped  # noqa: PLC0415

    try:
        parsed = parse_composite(target)
    except ValueError as exc:
        raise LoadError(f"{target}: {exc}") from None
    members = []
    for member, member_target in parsed.members:
        try:
            members.append((member, load_component_class(member_target, Component)))
        except LoadError as exc:
            raise LoadError(f"member {member}: {exc}") from exc.__cause__
    context = Stepped() if parsed.hz is None else Periodic(hz=parsed.hz)
    try:
        return composite_class(name, members, context)
    except SdrpeerError as exc:
        raise LoadError(f"{target}: {exc}") from None


def _load_module(target: str, where: str) -> ModuleType:
    """Import module `where`."""
    try:
        return importlib.import_module(where)
    except ModuleNotFoundError as exc:
        if exc.name is not None and where.startswith(exc.name):
            raise LoadError(f"{target}: no module named {exc.name!r}") from None
        raise LoadError(f"{target}: import failed: {type(exc).__name__}: {exc}") from exc
    except Exception as exc:
        raise LoadError(f"{target}: import failed: {type(exc).__name__}: {exc}") from exc


def _load_file(target: str, where: str) -> ModuleType:
    """Execute the Python file `where` as a new module."""
    path = os.path.abspath(where)
    if not os.path.isfile(path):
        raise LoadError(f"{target}: no such file {path}")
    stem = os.path.splitext(os.path.basename(path))[0]
    mod_name = stem if stem.isidentifier() else "_sdrpeer_target"
    if mod_name in sys.modules:
        mod_name = f"_sdrpeer_target_{mod_name}"
    spec = importlib.util.spec_from_file_location(mod_name, path)
    if spec is None or spec.loader is None:
        raise LoadError(f"{target}: {path} is not a loadable Python file")
    module = importlib.util.module_from_spec(spec)
    sys.modules[mod_name] = module
    sys.path.insert(0, os.path.dirname(path))
    try:
        spec.loader.exec_module(module)
    except Exception as exc:
        del sys.modules[mod_name]
        raise LoadError(f"{target}: {path} raised {type(exc).__name__}: {exc}") from exc
    return module


def _bases(base: type | tuple[type, ...]) -> tuple[type, ...]:
    return base if isinstance(base, tuple) else (base,)


def _names(base: type | tuple[type, ...]) -> str:
    return " or ".join(b.__name__ for b in _bases(base))


def _single_subclass(target: str, module: ModuleType, base: type | tuple[type, ...]) -> type:
    """The one subclass of `base` defined in `module`."""
    found = [
        obj
        for obj in vars(module).values()
        if inspect.isclass(obj)
        and issubclass(obj, base)
        and obj not in _bases(base)
        and obj.__module__ == module.__name__
    ]
    if len(found) == 1:
        return found[0]
    names = ", ".join(sorted(c.__name__ for c in found))
    if not found:
        raise LoadError(f"{target}: defines no subclass of {_names(base)}")
    raise LoadError(f"{target}: defines several {_names(base)} subclasses ({names}); name one")
