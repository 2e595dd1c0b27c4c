"""Finding the fleet on the local network without seed addresses: mDNS/DNS-SD (python-zeroconf),
as Serf's `-discover` does.

How it works: with `discover: true` (off by default) the agent advertises a DNS-SD service
`_sdrpeer._udp.local.` whose SRV and A records give its gossip address, and browses the same
type; every robot found is handed to `on_found(host, port)` (the agent joins what was found
while it is alone: a newcomer joins the fleet, the fleet does not chase it). The instance name
is random per run (`sdrpeer-<16 hex>`) and the TXT record holds only the protocol version: no
robot name, key id or metric is announced, so a listener learns only that an sdrpeer agent
listens at that address (what a port scan tells too). Discovery finds
addresses, nothing else: the join and everything after it is sealed with the cluster key, so a
robot of another fleet (or a forged announcement) costs one refused exchange (counted
`unknown_key` or `unauthenticated` by the robot that got it) and is never a member.

Interfaces: an agent bound to one address announces and listens on that address's interface
only; one bound to 0.0.0.0 on every interface with each non-loopback IPv4 address. Multicast
does not cross routers: discovery covers one network segment (one Wi-Fi network, one bridge).
python-zeroconf is imported only when discovery is on.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import secrets
import socket
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final

if TYPE_CHECKING:
    from zeroconf.asyncio import AsyncServiceBrowser, AsyncServiceInfo, AsyncZeroconf

__all__ = ["SERVICE", "Discovery"]

log = logging.getLogger("sdrpeer.agent.discovery")

SERVICE: Final = "_sdrpeer._udp.local."
RESOLVE_TIMEOUT_MS: Final = 3000
CLOSE_TIMEOUT: Final = 1.0
"""Seconds `stop` gives the goodbye announcements before it closes anyway."""
TXT_VERSION: Final = "1"


def _any_address(host: str) -> bool:
    return host in ("0.0.0.0", "")


class Discovery:
    """Advertise this agent's gossip address and report the others found (one per agent)."""

    def __init__(self, host: str, port: int, on_found: Callable[[str, int], None]) -> None:
        self.host = host
        """The gossip address bound (0.0.0.0: every interface)."""
        self.port = port
        self.on_found = on_found
        self.instance = f"sdrpeer-{secrets.token_hex(8)}"
        """This run's DNS-SD instance name (random: robot names are not announced)."""
        self.found: dict[str, tuple[str, int]] = {}
        """Every other agent found: instance name -> (host, port)."""
        self._zc: AsyncZeroconf | None = None
        self._browser: AsyncServiceBrowser | None = None
        self._info: AsyncServiceInfo | None = None
        self._tasks: set[asyncio.Task[None]] = set()

    async def start(self) -> None:
        """Start announcing and browsing (returns at once; probing goes on in the background).
        OSError when no multicast socket can be opened."""
        from zeroconf import IPVersion  # noqa: PLC0415 - only when discovery is on
        from zeroconf.asyncio import (  # noqa: PLC0415
            AsyncServiceBrowser,
            AsyncServiceInfo,
            AsyncZeroconf,
        )

        if self.host.startswith("127."):
            log.warning("discovery on a loopback address (%s) finds no other robot", self.host)
        interfaces: Any = "all" if _any_address(self.host) else [self.host]
        if interfaces == "all":
            from zeroconf import InterfaceChoice  # noqa: PLC0415

            interfaces = InterfaceChoice.All
        self._zc = zc = AsyncZeroconf(interfaces=interfaces, ip_version=IPVersion.V4Only)
        addresses = self._addresses()
        self._info = AsyncServiceInfo(
            SERVICE,
            f"{self.instance}.{SERVICE}",
            addresses=[socket.inet_aton(a) for a in addresses],
            port=self.port,
            properties={"v": TXT_VERSION},
            server=f"{self.instance}.local.",
        )
        self._browser = AsyncServiceBrowser(zc.zeroconf, SERVICE, handlers=[self._on_change])
        self._spawn(self._register())
        log.info("discovery: announcing %s at %s port %d", self.instance, addresses, self.port)

    def _addresses(self) -> list[str]:
        if not _any_address(self.host):
            return [self.host]
        import ifaddr  # noqa: PLC0415 - zeroconf's own dependency

        out = []
        for adapter in ifaddr.get_adapters():
            for ip in adapter.ips:
                if isinstance(ip.ip, str) and not ip.ip.startswith("127."):
                    out.append(ip.ip)
        return out

    async def _register(self) -> None:
        assert self._zc is not None
        assert self._info is not None
        try:
            await (await self._zc.async_register_service(self._info))
        except Exception as exc:  # a name clash, a closed socket: discovery of others goes on
            log.warning("discovery: cannot announce this agent: %r", exc)

    def _spawn(self, coro: Any) -> None:
        task = asyncio.get_running_loop().create_task(coro)
        self._tasks.add(task)
        task.add_done_callback(self._tasks.discard)

    def _on_change(self, **kwargs: Any) -> None:
        """ServiceBrowser's handler (called on the loop): resolve what was added or updated."""
        from zeroconf import ServiceStateChange  # noqa: PLC0415

        name = str(kwargs.get("name", ""))
        change = kwargs.get("state_change")
        if name.startswith(self.instance + "."):
            return  # ourselves
        if change is ServiceStateChange.Removed:
            self.found.pop(name, None)
        elif change in (ServiceStateChange.Added, ServiceStateChange.Updated):
            self._spawn(self._resolve(name))

    async def _resolve(self, name: str) -> None:
        from zeroconf.asyncio import AsyncServiceInfo  # noqa: PLC0415

        if self._zc is None:
            return
        info = AsyncServiceInfo(SERVICE, name)
        if not await info.async_request(self._zc.zeroconf, RESOLVE_TIMEOUT_MS):
            log.debug("discovery: %s did not resolve", name)
            return
        if (info.properties or {}).get(b"v") != TXT_VERSION.encode() or not info.port:
            return
        for host in info.parsed_addresses():
            if ":" in host:
                continue  # IPv4 only (as the gossip socket)
            self.found[name] = (host, info.port)
            self.on_found(host, info.port)
            return

    async def stop(self) -> None:
        """Stop browsing, say goodbye (bounded by CLOSE_TIMEOUT) and close the sockets."""
        for task in list(self._tasks):
            task.cancel()
        zc, self._zc = self._zc, None
        if zc is None:
            return
        with contextlib.suppress(TimeoutError, OSError, RuntimeError):
            async with asyncio.timeout(CLOSE_TIMEOUT):
                if self._browser is not None:
                    await self._browser.async_cancel()
                await zc.async_close()  # goodbyes for our service, then the sockets
