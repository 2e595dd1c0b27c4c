"""Port tools (`sdrpeer port ...`): list, connect, disconnect, print, inject, record, replay.

The agent does the work (sdrpeer.ports.routes: taps, injections, run-time connections, with its
data keys); the command line talks HTTP to it and writes or reads MCAP files
(sdrpeer.ports.mcapfile).
"""
