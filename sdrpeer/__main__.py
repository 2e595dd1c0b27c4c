"""`python -m sdrpeer` and the `sdrpeer` console script.

`sdrpeer agent ...` goes straight to `sdrpeer.cli.agent`, which loads only what the agent needs
(the whole command line costs tens of milliseconds more); every other command to `sdrpeer.cli.main`.
"""

import sys
from collections.abc import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point: dispatch `agent` to its fast path, the rest to the command line."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args[:1] == ["agent"]:
        from sdrpeer.cli.agent import main as agent  # noqa: PLC0415 - the fast path

        return agent(args[1:])
    from sdrpeer.cli.main import main as cli  # noqa: PLC0415 - everything else

    return cli(args)


if __name__ == "__main__":
    sys.exit(main())
