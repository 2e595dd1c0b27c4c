"""The control channel between an agent and each component host (docs/protocol.md, section 1).

messages.py: one frozen dataclass per message (commands agent -> host, reports host -> agent, `Part`
both ways). codec.py: the only code that turns them into msgpack maps and back, checking every
field. stream.py: the framing (maps out of a byte stream, the size limit). parts.py: big values cut
into `Part`s and put together again. host_side.py: the host's end (decoder of commands, asyncio
channel, heartbeat, parent-death signal). agent_side.py: the agent's end (decoder of reports,
commands awaiting their replies). Both ends import only this package and `sdrpeer.errors`; the host
imports it, so it stays light (msgpack and dataclasses).
"""
