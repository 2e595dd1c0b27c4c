"""Data stream addresses: ``tcp://HOST:PORT`` and ``unix:///path/to.sock``.

How it works: `parse_address` splits an address into its kind and target and says what is wrong
with a bad one; `format_tcp` writes the form the data server advertises for TCP.
"""

from __future__ import annotations

from typing import Literal

Kind = Literal["tcp", "unix"]


def parse_address(address: str) -> tuple[Kind, str, int]:
    """(kind, host or path, port) of an address; ValueError naming the problem when it is bad."""
    if address.startswith("unix://"):
        path = address[len("unix://") :]
        if not path.startswith("/"):
            raise ValueError(f"data address {address!r}: unix path must be absolute")
        return "unix", path, 0
    if address.startswith("tcp://"):
        host, sep, port = address[len("tcp://") :].rpartition(":")
        if not sep or not host or not port.isdigit() or not 0 < int(port) < 65536:
            raise ValueError(f"data address {address!r}: expected tcp://HOST:PORT")
        return "tcp", host.strip("[]"), int(port)
    raise ValueError(f"data address {address!r}: expected tcp://HOST:PORT or unix:///path")


def format_tcp(host: str, port: int) -> str:
    """The advertised form of a TCP listener (HOST:PORT, IPv6 hosts in brackets)."""
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"
