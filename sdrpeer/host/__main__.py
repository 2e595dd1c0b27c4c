"""Entry point: `python -m sdrpeer.host pkg.mod:Class [--param k=v ...] [--name NAME]`."""

from sdrpeer.host.lean import import_asyncio

import_asyncio()  # before anything else imports asyncio: no OpenSSL unless the component needs it

from sdrpeer.host.main import main  # noqa: E402

raise SystemExit(main())
