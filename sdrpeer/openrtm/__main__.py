"""Entry point: `python -m sdrpeer.openrtm path/to/Module.py[:TypeName] [--param k=v ...]`."""

from sdrpeer.openrtm.host import main

raise SystemExit(main())
