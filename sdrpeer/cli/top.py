"""`sdrpeer top`: the fleet's robots and components, live, redrawn in place.

How it works: it reads the agent's server-sent event stream (`GET /v1/stream`, the dashboard's:
one sample a second pushed by the agent, no polling) and draws each `sample` with
`sdrpeer.cli.status.format_top`. On a terminal the screen is cleared and redrawn; piped, each
screen is
printed after the last, separated by a blank line. `--iterations N` stops after N screens. A
dropped stream is reopened (after a second) until the time given by `--reconnect` runs out.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import urllib.error
import urllib.request
from collections.abc import Iterator
from typing import IO, Any

from sdrpeer.cli.common import endpoint
from sdrpeer.cli.format import want_color
from sdrpeer.client import unreachable_message
from sdrpeer.errors import ApiError

CLEAR = "\x1b[H\x1b[2J"


def read_stream(lines: IO[bytes]) -> Iterator[tuple[str, Any]]:
    """(event, decoded data) of each server-sent event on `lines`."""
    kind, data = "message", ""
    for raw in lines:
        line = raw.decode("utf-8", "replace").rstrip("\r\n")
        if not line:
            if data:
                yield kind, json.loads(data)
            kind, data = "message", ""
        elif line.startswith("event:"):
            kind = line[6:].strip()
        elif line.startswith("data:"):
            data += line[5:].strip()


def samples(api: str, reconnect_s: float) -> Iterator[dict[str, Any]]:
    """Every `sample` of the agent's stream, reopening a dropped stream for up to `reconnect_s`."""
    deadline = time.monotonic() + reconnect_s
    while True:
        request = urllib.request.Request(
            api.rstrip("/") + "/v1/stream", headers={"Accept": "text/event-stream"}
        )
        try:
            with urllib.request.urlopen(request, timeout=30) as stream:
                deadline = time.monotonic() + reconnect_s
                for kind, data in read_stream(stream):
                    if kind == "sample":
                        yield data
        except urllib.error.HTTPError as exc:
            raise ApiError(f"agent at {api} answered {exc.code} to /v1/stream") from None
        except (urllib.error.URLError, OSError) as exc:
            if time.monotonic() > deadline:
                raise ApiError(unreachable_message(api, getattr(exc, "reason", exc))) from None
        time.sleep(1.0)


def run_top(api: str, iterations: int | None, reconnect_s: float, out: IO[str]) -> int:
    """Draw screens until `iterations` (None: until interrupted)."""
    from sdrpeer.cli.status import format_top  # noqa: PLC0415 - the parser stays light

    color = want_color(out.isatty(), os.environ)
    for shown, sample in enumerate(samples(api, reconnect_s), start=1):
        screen = format_top(sample, color=color)
        if out.isatty():
            out.write(CLEAR + screen + "\n")
        else:
            out.write(("\n" if shown > 1 else "") + screen + "\n")
        out.flush()
        if iterations is not None and shown >= iterations:
            break
    return 0


def add_top_parser(sub: Any, client: argparse.ArgumentParser) -> None:
    """`sdrpeer top`."""
    top = sub.add_parser("top", parents=[client], help="robots and components, live")
    top.add_argument("--iterations", "-n", type=int, metavar="N", help="stop after N screens")
    top.add_argument(
        "--reconnect", type=float, default=30.0, metavar="S", help="retry a lost stream for S s"
    )
    top.set_defaults(func=cmd_top)


def cmd_top(args: argparse.Namespace) -> int:
    """Show the fleet live."""

    return run_top(endpoint(args).api, args.iterations, args.reconnect, sys.stdout)
