"""A host loads OpenSSL only when its component needs it, and then asyncio's TLS works as usual."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

from tests.hostctl import ROOT, HostPool

FX = "tests.components_fixture"


def run_python(code: str) -> str:
    """Run `code` in a fresh interpreter (the repository importable); its stdout."""
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(code)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=30,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def openssl_mapped(pid: int) -> list[str]:
    """OpenSSL libraries mapped by a process."""
    maps = Path(f"/proc/{pid}/maps").read_text()
    return sorted({line.split()[-1] for line in maps.splitlines() if "libssl" in line})


def test_an_idle_host_maps_no_openssl(tmp_path: Path) -> None:
    pool = HostPool(tmp_path)
    try:
        host = pool.spawn(f"{FX}:Counter")
        host.wait_state("INACTIVE")
        assert openssl_mapped(host.proc.pid) == []
    finally:
        pool.close_all()


def test_asyncio_without_ssl_gets_it_when_something_imports_ssl() -> None:
    out = run_python(
        """
        import sys
        from sdrpeer.host.lean import import_asyncio
        import_asyncio()
        import asyncio, asyncio.sslproto as proto
        print("before", "ssl" in sys.modules, proto.ssl is None)

        def later():  # an import long after start-up, as a component's function might do
            import ssl
            return ssl

        ssl = later()
        print("after", proto.ssl is ssl, asyncio.base_events.ssl is ssl,
              asyncio.selector_events.ssl is ssl,
              proto.SSLAgainErrors == (ssl.SSLWantReadError, ssl.SSLSyscallError))

        async def handshake():  # a real TLS client handshake against a server that is not TLS
            async def garbage(reader, writer):
                writer.write(b"this is not TLS\\r\\n" * 64)
                await writer.drain()
                writer.close()
            server = await asyncio.start_server(garbage, "127.0.0.1", 0)
            port = server.sockets[0].getsockname()[1]
            context = ssl.create_default_context()
            try:
                await asyncio.open_connection("127.0.0.1", port, ssl=context,
                                              server_hostname="localhost")
            except ssl.SSLError as exc:  # the handshake ran in asyncio's ssl protocol
                print("handshake", type(exc).__name__)
            finally:
                server.close()

        asyncio.run(handshake())
        """
    )
    assert out.splitlines() == [
        "before False True",
        "after True True True True",
        "handshake SSLError",
    ]


def test_import_asyncio_changes_nothing_when_asyncio_is_already_imported() -> None:
    out = run_python(
        """
        import sys, asyncio, asyncio.sslproto as proto
        from sdrpeer.host.lean import import_asyncio
        before = list(sys.meta_path)
        import_asyncio()
        print(sys.meta_path == before, proto.ssl is sys.modules["ssl"])
        """
    )
    assert out.split() == ["True", "True"]
