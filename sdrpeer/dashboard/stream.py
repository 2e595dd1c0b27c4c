"""Server-sent events: one stream per dashboard, fed by the agent as things happen.

How it works: `Hub.publish(kind, data, id)` encodes a message once (`event: kind`, `id:` for
log entries, `data: <JSON>`) and puts it in every client's queue. Each client's queue is bounded:
a client too slow to keep up is dropped (its browser reconnects and catches up from
`Last-Event-ID` and the history), so one stuck page can neither grow the agent's memory nor slow
the others. `serve(request, hello)` answers `GET /v1/stream`: it writes `hello()`'s messages
(what a new page needs first), then whatever is published, with a comment line every
`keepalive_s` so proxies and browsers keep the connection; the number of clients is capped.
`serve(..., once=True)` writes `hello()`'s messages and an `end` message, then ends the response:
a page in snapshot mode gets one consistent picture and nothing keeps it loading (a headless
browser's `--virtual-time-budget` waits for open requests).
"""

from __future__ import annotations

import asyncio
import json
from collections.abc import Callable, Iterable
from typing import Any, Final

from aiohttp import web

__all__ = ["Hub", "encode_event"]

_CLOSE: Final = b""


def encode_event(kind: str, data: Any, event_id: int | None = None) -> bytes:
    """One SSE message."""
    text = json.dumps(data, separators=(",", ":"), default=str)
    head = f"event: {kind}\n" + (f"id: {event_id}\n" if event_id is not None else "")
    return f"{head}data: {text}\n\n".encode()


class Hub:
    """The live streams of one agent."""

    def __init__(
        self, *, max_clients: int = 16, queue_len: int = 512, keepalive_s: float = 15.0
    ) -> None:
        self.max_clients = max_clients
        self.queue_len = queue_len
        self.keepalive_s = keepalive_s
        self.counters = {"published": 0, "dropped_clients": 0, "refused_clients": 0}
        self._clients: set[asyncio.Queue[bytes]] = set()

    @property
    def clients(self) -> int:
        """Streams open now."""
        return len(self._clients)

    def publish(self, kind: str, data: Any, event_id: int | None = None) -> None:
        """Send a message to every client (nothing is encoded when nobody listens)."""
        if not self._clients:
            return
        message = encode_event(kind, data, event_id)
        self.counters["published"] += 1
        for queue in list(self._clients):
            if queue.qsize() >= self.queue_len:  # too slow: it gets what it has, then the end
                self._clients.discard(queue)
                self.counters["dropped_clients"] += 1
                queue.put_nowait(_CLOSE)  # the queue keeps one place for this
            else:
                queue.put_nowait(message)

    def close(self) -> None:
        """End every stream (the agent is stopping)."""
        for queue in list(self._clients):
            self._clients.discard(queue)
            queue.put_nowait(_CLOSE)

    async def serve(
        self,
        request: web.Request,
        hello: Callable[[str | None], Iterable[bytes]],
        *,
        once: bool = False,
    ) -> web.StreamResponse:
        """GET /v1/stream: `hello(last_event_id)` first, then everything published (`once`:
        then an `end` message, and the response ends)."""
        if len(self._clients) >= self.max_clients:
            self.counters["refused_clients"] += 1
            raise web.HTTPServiceUnavailable(reason=f"at most {self.max_clients} streams")
        response = web.StreamResponse(
            headers={
                "Content-Type": "text/event-stream",
                "Cache-Control": "no-cache",
                "X-Accel-Buffering": "no",
            }
        )
        await response.prepare(request)
        if once:
            for message in hello(request.headers.get("Last-Event-ID")):
                await response.write(message)
            await response.write(encode_event("end", {}))
            await response.write_eof()
            return response
        queue: asyncio.Queue[bytes] = asyncio.Queue(self.queue_len + 1)
        self._clients.add(queue)
        try:
            await response.write(b"retry: 2000\n\n")
            for message in hello(request.headers.get("Last-Event-ID")):
                await response.write(message)
            while True:
                try:
                    async with asyncio.timeout(self.keepalive_s):
                        message = await queue.get()
                except TimeoutError:
                    message = b": keepalive\n\n"
                if message == _CLOSE:
                    break
                await response.write(message)
        except ConnectionResetError:
            pass  # the page went away
        finally:
            self._clients.discard(queue)
        return response
