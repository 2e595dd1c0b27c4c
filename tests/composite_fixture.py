"""Members for composite tests: each appends `Name.callback` to a journal the test can read, a
source, a doubler that passes values on, a sink, and one that fails on demand."""

from __future__ import annotations

import os
from typing import Any, ClassVar

from sdrpeer.sdk import Component, InPort, OnInput, OutPort, Param, Stepped


class Journaled(Component):
    """Writes every callback it gets into the shared `JOURNAL` (tests clear it)."""

    JOURNAL: ClassVar[list[str]] = []

    def _note(self, what: str) -> None:
        Journaled.JOURNAL.append(f"{type(self).__name__}.{what}")

    def on_initialize(self) -> None:
        self._note("on_initialize")

    def on_startup(self) -> None:
        self._note("on_startup")

    def on_activated(self) -> None:
        self._note("on_activated")

    def on_deactivated(self) -> None:
        self._note("on_deactivated")

    def on_aborting(self) -> None:
        self._note("on_aborting")

    def on_reset(self) -> None:
        self._note("on_reset")

    def on_shutdown(self) -> None:
        self._note("on_shutdown")

    def on_finalize(self) -> None:
        self._note("on_finalize")


class Source(Journaled):
    """Writes 1, 2, 3, ... on `out`, one per execution; keeps its count across a handoff."""

    execution = Stepped()  # ignored inside a composite: the composite's context runs it
    out = OutPort("the count")
    step = Param(int, 1, "added per execution", min=1)

    def on_initialize(self) -> None:
        super().on_initialize()
        self.n = 0

    def on_execute(self) -> None:
        self._note("on_execute")
        self.n += self.step
        self.out.write(self.n)

    def on_snapshot(self) -> dict[str, int]:
        return {"n": self.n}

    def on_restore(self, state: Any) -> None:
        self.n = int(state["n"])


class Doubler(Journaled):
    """Writes twice every value that arrived on `inp` to `out`; `fail_at` makes it raise."""

    execution = OnInput("inp")  # ignored inside a composite
    inp = InPort("numbers", policy={"buffer": 1000})
    out = OutPort("doubled numbers")
    fail_at = Param(int, 0, "raise in on_execute when this value arrives (0: never)")
    gain = Param(int, 2, "the factor", on_change="gain_changed")

    def on_initialize(self) -> None:
        super().on_initialize()
        self.gains: list[int] = []

    def gain_changed(self, value: int) -> None:
        self.gains.append(value)

    def on_execute(self) -> None:
        self._note("on_execute")
        while self.inp.qsize():
            value = self.inp.get_nowait()
            if value == self.fail_at:
                raise ValueError(f"cannot double {value}")
            self.out.write(value * self.gain)


class Sink(Journaled):
    """Keeps what arrives on `inp`."""

    inp = InPort("anything", policy={"buffer": 1000})

    def on_initialize(self) -> None:
        super().on_initialize()
        self.values: list[Any] = []

    def on_execute(self) -> None:
        self._note("on_execute")
        while self.inp.qsize():
            self.values.append(self.inp.get_nowait())


class Stuck(Journaled):
    """Cannot be activated."""

    def on_activated(self) -> None:
        super().on_activated()
        raise RuntimeError("the device is not there")


class Alarm(Journaled):
    """Reports an emergency stop on its first execution."""

    def on_execute(self) -> None:
        self.emergency_stop("bumper pressed")


class Tripwire(Component):
    """Raises in `on_execute` once the file `trigger` exists, removing it (so only one instance
    trips: its successor runs on)."""

    trigger = Param(str, "", "a file whose appearance trips this member")

    def on_execute(self) -> None:
        if self.trigger and os.path.exists(self.trigger):
            os.remove(self.trigger)
            raise RuntimeError("tripped")
