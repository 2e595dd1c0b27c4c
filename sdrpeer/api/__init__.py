"""The agent's HTTP API: JSON under /v1, Prometheus text at /metrics.

Importing this package imports aiohttp with OpenSSL pointed at no CA store. aiohttp builds two
*client* TLS contexts at import time, each loading the system CA bundle (about 2 MiB of resident
memory on a Raspberry Pi-class robot). The agent only serves plain HTTP on loopback and never
opens TLS connections, so that memory would be dead weight. The environment is restored at once,
so nothing else in the process, and no child process, is affected.
"""

from __future__ import annotations

import os
import sys


def _import_aiohttp_without_ca_store() -> None:
    if "aiohttp" in sys.modules:
        return
    saved = {k: os.environ.get(k) for k in ("SSL_CERT_FILE", "SSL_CERT_DIR")}
    os.environ["SSL_CERT_FILE"] = os.devnull
    os.environ["SSL_CERT_DIR"] = os.devnull
    try:
        import aiohttp.web  # noqa: F401, PLC0415
    finally:
        for key, value in saved.items():
            if value is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = value


_import_aiohttp_without_ca_store()
