"""`python -m sdrpeer`: the same as the `sdrpeer` command."""

import sys

from sdrpeer.cli import main

if __name__ == "__main__":
    sys.exit(main())
