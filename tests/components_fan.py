"""Components with many ports, for the dashboard's browser test: a topology with a dozen
connections from three host processes."""

from __future__ import annotations

from sdrpeer.sdk import Component, InPort, OutPort, Param, Periodic

PORTS = ("a", "b", "c", "d", "e", "f")
"""The port names of both classes."""


class Fan(Component):
    """Publishes 1, 2, 3, ... on each of its six OutPorts at `rate` Hz."""

    execution = Periodic(param="rate")
    rate = Param(float, 10.0, "frames per second on each port")
    a = OutPort("the count")
    b = OutPort("the count")
    c = OutPort("the count")
    d = OutPort("the count")
    e = OutPort("the count")
    f = OutPort("the count")

    def on_initialize(self) -> None:
        """Start from zero."""
        self.n = 0

    def on_execute(self) -> None:
        """Publish the next number on every port."""
        self.n += 1
        for name in PORTS:
            getattr(self, name).write(self.n)


class Sink(Component):
    """Takes whatever waits on its six InPorts, ten times a second."""

    execution = Periodic(hz=10.0)
    a = InPort("anything")
    b = InPort("anything")
    c = InPort("anything")
    d = InPort("anything")
    e = InPort("anything")
    f = InPort("anything")

    def on_initialize(self) -> None:
        """Nothing taken yet."""
        self.taken = 0

    def on_execute(self) -> None:
        """Drain every port."""
        for name in PORTS:
            port = getattr(self, name)
            while port.qsize():
                port.get_nowait()
                self.taken += 1
