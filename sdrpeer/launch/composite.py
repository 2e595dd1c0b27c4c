"""The `composite` launcher and its target: several member classes run by one host process.

How it works: a composite's target is one line of text, `CONTEXT;Member=pkg.mod:Class;...`, with
the shared execution context first (`periodic:HZ` or `stepped`) and the members after it in
execution order, e.g. `periodic:20;Cam=components.camera:Camera;Det=components.detector:Detector`.
`parse_composite` checks it (member names are identifiers, unique; targets `pkg.mod:Class`) and
raises ValueError saying what is wrong; `CompositeTarget.text()` is its inverse. The `composite`
launcher (sdrpeer.launch.launchers) starts `python -m sdrpeer.host --composite TARGET --param
Member.param=v ...`; the host builds the
composite class out of the members (sdrpeer.sdk.composite). The system file's `composites:`
section (docs/system-file.md) writes these targets; an instance spec may give one directly.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass

__all__ = ["CompositeTarget", "parse_composite"]

_MEMBER = re.compile(r"^[A-Za-z_][A-Za-z0-9_]{0,63}$")
_PY_TARGET = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_]\w*$")


@dataclass(frozen=True, slots=True)
class CompositeTarget:
    """A composite's shared execution context and its members, in execution order."""

    hz: float | None
    """The periodic context's rate in Hz; None: a stepped context."""
    members: tuple[tuple[str, str], ...]
    """(member name, `pkg.mod:Class`) in execution order."""

    def text(self) -> str:
        """The target as `parse_composite` reads it."""
        context = "stepped" if self.hz is None else f"periodic:{self.hz:g}"
        return ";".join([context, *(f"{m}={t}" for m, t in self.members)])


def parse_composite(text: str) -> CompositeTarget:
    """Read a composite target (see the module doc); ValueError naming what is wrong."""
    context, *items = [part.strip() for part in text.split(";")]
    hz: float | None = None
    if context != "stepped":
        kind, _, rate = context.partition(":")
        try:
            hz = float(rate) if kind == "periodic" else math.nan
        except ValueError:
            hz = math.nan
        if not (math.isfinite(hz) and hz > 0):
            raise ValueError(
                f"the context must be 'stepped' or 'periodic:HZ' (HZ > 0), got {context!r}"
            )
    if not items:
        raise ValueError("a composite needs at least one member ('Name=pkg.mod:Class')")
    members: list[tuple[str, str]] = []
    for item in items:
        name, eq, target = item.partition("=")
        if not eq or not _MEMBER.match(name):
            raise ValueError(f"expected Member=pkg.mod:Class with an identifier, got {item!r}")
        if not _PY_TARGET.match(target):
            raise ValueError(f"member {name}: expected package.module:Class, got {target!r}")
        if any(name == m for m, _ in members):
            raise ValueError(f"member {name!r} given twice")
        members.append((name, target))
    return CompositeTarget(hz, tuple(members))
