"""Entry point: `python -m sdrpeer.host pkg.mod:Class [--param k=v ...] [--name NAME]`."""

from sdrpeer.host.main import main

raise SystemExit(main())
