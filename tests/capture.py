"""A packet capture on the loopback interface (root: a raw AF_PACKET socket), for tests that
check what an eavesdropper in radio range would read: every UDP and TCP payload to or from the
given ports, as bytes, in the order seen."""

from __future__ import annotations

import os
import select
import socket
import struct
import threading
from collections.abc import Iterable
from types import TracebackType

import pytest

ROOT_ONLY = pytest.mark.skipif(
    os.geteuid() != 0, reason="PACKET CAPTURE NOT TESTED: a raw socket needs root"
)
"""Marks a test that captures packets."""

_ETH_P_ALL = 0x0003
_ETH_HEADER = 14


class Capture:
    """Payloads of IPv4 UDP and TCP packets on `lo` whose source or destination port is one of
    `ports` (more can be added while it runs: `ports.add`)."""

    def __init__(self, ports: Iterable[int] = ()) -> None:
        self.ports = set(ports)
        self.payloads: list[bytes] = []
        self._sock = socket.socket(socket.AF_PACKET, socket.SOCK_RAW, socket.htons(_ETH_P_ALL))
        self._sock.bind(("lo", 0))
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
            payload = self._payload(frame)
            if payload:
                self.payloads.append(payload)

    def _payload(self, frame: bytes) -> bytes | None:
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
            return body
        return None
