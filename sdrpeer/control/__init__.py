"""The control channel between an agent and each component host: framing (stream.py) and
values split into parts (parts.py)."""
