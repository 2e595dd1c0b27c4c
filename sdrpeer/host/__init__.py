"""The component host: one process per component instance, driven by its agent.

How it works: `python -m sdrpeer.host TARGET` (see `main`) loads the component class, starts the
instance's data server and speaks the control channel (`sdrpeer.control.host_side`) with the
agent that started it; `serve` runs the command loop and the exit path. This package imports
nothing heavy at import time.
"""
