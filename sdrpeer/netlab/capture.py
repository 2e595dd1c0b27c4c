"""A packet capture on a network interface (root: a raw AF_PACKET socket): what an eavesdropper
in radio range reads, and what it could replay.

How it works: a thread reads every frame of the interface (`lo` by default) and keeps the payload
of each IPv4 UDP or TCP packet whose source or destination port is one of `ports` (more can be
added while it runs), in the order seen; UDP datagrams are also kept with their ports, so a
datagram captured on its way to one robot can be sent again to another (tools/bench_replay.py,
tests/test_replay_realnet.py, tests/test_confidential.py). Loopback shows each packet twice; the
outgoing copy is skipped.
"""

from __future__ import annotations

import select
import socket
import struct
import threading
from collections.abc import Iterable
from types import TracebackType

_ETH_P_ALL = 0x0003
_ETH_HEADER = 14


class Capture:
    """Payloads of IPv4 UDP and TCP packets on `interface` whose source or destination port is
    one of `ports` (more can be added while it runs: `ports.add`)."""

    def __init__(self, ports: Iterable[int] = (), interface: str = "lo") -> None:
        self.ports = set(ports)
        self.payloads: list[bytes] = []
        self.datagrams: list[tuple[int, int, bytes]] = []
        """UDP datagrams seen: (source port, destination port, payload)."""
        self._sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(_ETH_P_ALL))
        self._sock.bind((interface, 0))
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="capture", daemon=True)

    def __enter__(self) -> Capture:
        self._thread.start()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._stop.set()
        self._thread.join(5)
        self._sock.close()

    def joined(self) -> bytes:
        """Every payload captured so far, one after the other."""
        return b"".join(list(self.payloads))

    def _run(self) -> None:
        while not self._stop.is_set():
            ready, _, _ = select.select([self._sock], [], [], 0.1)
            if not ready:
                continue
            frame, meta = self._sock.recvfrom(65535)
            if meta[2] == socket.PACKET_OUTGOING:
                continue  # loopback shows each packet twice: keep the incoming copy
            seen = self._payload(frame)
            if seen is None:
                continue
            udp, sport, dport, payload = seen
            if payload:
                self.payloads.append(payload)
            if udp:
                self.datagrams.append((sport, dport, payload))

    def to_port(self, port: int) -> list[bytes]:
        """The UDP payloads seen on their way to `port`, in order."""
        return [data for _, dport, data in list(self.datagrams) if dport == port]

    def _payload(self, frame: bytes) -> tuple[bool, int, int, bytes] | None:
        """(UDP?, source port, destination port, payload) of a frame to or from our ports."""
        ip = frame[_ETH_HEADER:]
        if len(ip) < 20 or ip[0] >> 4 != 4:
            return None
        ihl = (ip[0] & 0x0F) * 4
        proto = ip[9]
        total = struct.unpack("!H", ip[2:4])[0]
        segment = ip[ihl:total]
        if proto == socket.IPPROTO_UDP and len(segment) >= 8:
            sport, dport = struct.unpack("!HH", segment[:4])
            body = segment[8:]
        elif proto == socket.IPPROTO_TCP and len(segment) >= 20:
            sport, dport = struct.unpack("!HH", segment[:4])
            body = segment[(segment[12] >> 4) * 4 :]
        else:
            return None
        if sport in self.ports or dport in self.ports:
            return proto == socket.IPPROTO_UDP, sport, dport, body
        return None
