"""The sending side of one data stream: an OutPort's sink that writes frames to a receiver.

How it works: an asyncio shell around a `FrameWriter` (packing, policy queue, numbering,
joining). `offer(value)` encodes the value at once (so an oversized or unencodable value is
refused right there, with an error naming the connection) and queues it. Writing is not a task
per frame: the first offer in a loop iteration writes its frame immediately when the link is
idle (low latency: with nothing pending, a small value skips the queue and is written as it is
packed) and schedules one `call_soon` flush that writes everything offered meanwhile in one
`transport.write` (high throughput). The transport keeps no backlog of its own
(high-water mark 0): when the kernel's socket buffer is full, writing pauses until it drained
and values wait in the queue, where the policy decides (so `new` really sends the newest value,
not one stuck in a user-space buffer).

A supervisor task owns the socket: it dials `to`, writes the hello, waits for the ok, then sleeps
until the link drops, `repoint` changes the address, or `close` is called. A drop is redialed
with exponential backoff (pending values stay queued, up to the buffer; frames lost inside the
dead socket show up as a gap in seq at the receiver). A dial the receiver refuses (its error
reply, a proof that does not hold, encryption refused) is redialed likewise, and each refusal
goes to `refusals.on_refused` with its reason (`None` once a dial gets through again), so that
the host can tell its agent. `release()` (the host is exiting) makes `drain` return at once
from then on: a component blocked in `send()` on a connection that cannot take a frame lets
go. `repoint`
detaches the link at once, so later frames wait for the new peer, and shuts the old link, which
still delivers what it was handed. seq counts frames written to this connection, starting at 1,
across redials. The socket itself (and, on a Unix socket, the shared-memory ring big values
take) is `link.Link`'s.

Acknowledged streams (push all/fifo, when the receiver agrees): the writer keeps every frame
until the receiver acknowledges it (sdrpeer.dataplane.retention), and writes nothing more while
the window is full. A repointed link is only half-closed and kept (`_draining`) so the old
receiver's last acknowledgements arrive; the next dial waits until it closed (at most
`drain_timeout`, then it is aborted), and the new link first gets every frame still
unacknowledged, with its seq, then what is pending. A planned move so loses no frame, and one
after a crash of the receiver loses none the window held; the receiver's port drops a frame it
already has (a reconnect to the same instance) and counts it in `duplicates`.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os

from sdrpeer.dataplane.address import parse_address
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.dataplane.frames import DEFAULT_MAX_FRAME, AckOffer, Hello
from sdrpeer.dataplane.link import Link, dial
from sdrpeer.dataplane.pending import PolicyLike
from sdrpeer.dataplane.refusals import DialRefusals
from sdrpeer.dataplane.retention import DEFAULT_BYTES, DEFAULT_FRAMES, Retention
from sdrpeer.dataplane.shm import DEFAULT_SIZE
from sdrpeer.dataplane.writer import FrameWriter
from sdrpeer.errors import FrameError

log = logging.getLogger("sdrpeer.dataplane")


def next_backoff(delay: float, initial: float, cap: float) -> float:
    """The redial delay after `delay` failed: doubled, at least `initial`, at most `cap`."""
    return min(cap, max(initial, delay * 2))


class Connection:
    """A FrameSink that sends an OutPort's values to one InPort, per a connector policy."""

    def __init__(
        self,
        conn_id: str,
        to: str,
        in_port: str,
        from_: str,
        policy: PolicyLike,
        *,
        max_frame: int = DEFAULT_MAX_FRAME,
        backoff: tuple[float, float] = (0.05, 2.0),
        hello_timeout: float = 5.0,
        shm_size: int = DEFAULT_SIZE,
        window: tuple[int, int] | None = (DEFAULT_FRAMES, DEFAULT_BYTES),
        drain_timeout: float = 5.0,
        auth: DataAuth | None = None,
        given: dict[str, object] | None = None,
        type_id: str | None = None,
    ) -> None:
        parse_address(to)
        self.conn_id = conn_id
        self.to = to
        self.in_port = in_port
        self.from_ = from_
        self.policy = policy
        self.max_frame = max_frame
        self.backoff = backoff
        self.hello_timeout = hello_timeout
        self.shm_size = shm_size
        """Bytes of the shared-memory ring offered on a Unix socket (0: none)."""
        self.window = window if policy.push in ("all", "fifo") else None
        """(frames, bytes) kept until acknowledged; None: no acknowledgements asked for."""
        self.drain_timeout = drain_timeout
        """Seconds a repointed link may take to deliver its last acknowledgements."""
        self.auth = auth
        """The host's data keys (sdrpeer.dataplane.auth); with any, links are authenticated."""
        self.type_id = type_id
        """The sending port's message type id, told in the hello (None: any value)."""
        self.given = {} if given is None else dict(given)
        """The policy map the hello carries: the keys the connection sets itself (a system
        file's `policy:`; none by default); the receiving InPort applies its `buffer` and `full`
        over its own declared policy."""
        self.session = os.urandom(8).hex()
        """This sender's stream session (a receiver tells a replay from a restart by it)."""
        self.reconnects = 0
        """Successful redials after a dropped link."""
        self.refused = 0
        """Values refused at `offer` because they were oversized or unencodable."""
        self.last_error: str | None = None
        """Why the last dial or link failed."""
        self.refusals = DialRefusals(conn_id)
        """Dials the receiver refused (sdrpeer.dataplane.refusals), told to its `on_refused`."""
        self._released = False
        self.dropped_remote = 0
        """Frames the receiving InPort's policy discarded (overwrite, drop, skip, new), as its
        acknowledgements counted them: with `dropped`, every frame this connection lost to a
        policy (an ack lost with a broken link loses its count)."""
        self._writer = FrameWriter(policy, max_frame)
        self._queue = self._writer.queue
        self._writer_offer = self._writer.offer
        self._link: Link | None = None
        self._draining: set[Link] = set()
        self._paused = self._never
        self._scheduled = False
        self._closing = False
        self._wake = asyncio.Event()
        self._room = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._loop: asyncio.AbstractEventLoop  # set by start

    @property
    def dropped(self) -> int:
        """Values discarded by the policy."""
        return self._queue.dropped

    @property
    def evicted(self) -> int:
        """Of those, values queued and then evicted for a newer one (overwrite, new): `offer`
        had returned True for them, so the OutPort did not count them."""
        return self._queue.evicted

    @property
    def overflowed(self) -> int:
        """Values lost at either end because a buffer was full: this queue's overwrites and
        drops, and the receiving InPort's (`dropped_remote`). Not what `new` and `skip` thin
        out by design. A connection that starts overflowing is warned about (port.overflow)."""
        return self._queue.overflowed + self.dropped_remote

    @property
    def frames_out(self) -> int:
        """Frames handed to a socket."""
        return self._writer.frames_out

    @property
    def bytes_out(self) -> int:
        """Bytes of those frames."""
        return self._writer.bytes_out

    @property
    def seq(self) -> int:
        """The seq of the last frame written (0 before the first)."""
        return self._writer.seq

    @property
    def pending(self) -> int:
        """Values waiting for the socket (a big one half written counts too)."""
        return self._writer.pending

    @property
    def replayed(self) -> int:
        """Frames written again to a new link because they had not been acknowledged."""
        return self._writer.replayed

    @property
    def unacked(self) -> int:
        """Frames written and not acknowledged yet (0 when the receiver does not acknowledge)."""
        retention = self._writer.retention
        return len(retention) if retention is not None else 0

    @property
    def connected(self) -> bool:
        """True while a link has said ok and not dropped."""
        return self._link is not None

    def start(self) -> None:
        """Start dialing (needs a running event loop); `offer` may be called before or after."""
        if self._task is None:
            self._loop = asyncio.get_running_loop()
            self._task = self._loop.create_task(self._run(), name=self.conn_id)

    def offer(self, value: object) -> bool:
        """Queue a value per the policy; False when dropped or (full=block) not queued yet."""
        if self._closing:
            return False
        if self._scheduled:  # the hot path: a flush comes this loop iteration
            try:
                return self._writer_offer(value)
            except FrameError as exc:
                raise self._refused(exc) from None
        link = self._link
        try:
            if link is None or link.paused:
                queued = self._writer_offer(value)
            else:  # an idle link: a small value goes out at once
                queued = self._writer.offer_now(value, link.write)
        except FrameError as exc:
            raise self._refused(exc) from None
        if queued and link is not None:
            self._scheduled = True
            if self._queue.items:
                self._flush()  # an idle link: what was queued goes out now
            self._loop.call_soon(self._flush_soon)  # what else is offered now goes out together
        return queued

    def _refused(self, exc: FrameError) -> FrameError:
        self.refused += 1
        where = f"connection {self.conn_id} ({self.from_} -> {self.in_port})"
        return FrameError(exc.reason, f"{where}: {exc.detail}")

    async def drain(self) -> None:
        """Wait until the queue has room (returns at once when it has, when closing, or once
        released)."""
        while not self._queue.has_room and not self._closing and not self._released:
            self._room.clear()
            await self._room.wait()

    def release(self) -> None:
        """Stop making writers wait (the host is exiting): `drain` returns at once from now on
        (until `hold`), and a value offered to a full `block` queue is refused (counted in
        `dropped`)."""
        self._released = True
        self._room.set()

    def hold(self) -> None:
        """Make writers wait for room again (undoes `release`)."""
        self._released = False

    def repoint(self, to: str) -> None:
        """Send later frames to `to`; frames already written still reach the old receiver."""
        parse_address(to)
        self.to = to
        link, self._link = self._link, None
        if link is not None:
            self._writer.finish_frame(link.write)  # the old receiver gets all of it
            if link.acks:
                self._draining.add(link)
            link.shut()
        self._wake.set()

    async def wait_connected(self) -> None:
        """Wait until a link is up (bound it with `asyncio.timeout`)."""
        while self._link is None:
            self._wake.clear()
            await self._wake.wait()

    async def flushed(self) -> None:
        """Wait until nothing is pending (everything was handed to a socket)."""
        while self.pending and not self._closing:
            self._room.clear()
            await self._room.wait()

    async def close(self, linger: float = 1.0) -> None:
        """Flush what is pending (for up to `linger` seconds if connected) and close the link."""
        if self._link is not None and self.pending:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(linger):
                    await self.flushed()
        self._closing = True
        self._room.set()
        self._wake.set()
        link, self._link = self._link, None
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        for old in self._draining:
            old.transport.abort()
        self._draining.clear()
        if link is not None:
            if link.ring is None and not link.acks:
                link.transport.close()  # what was written still arrives; no ack is awaited
            else:  # half-closed: the receiver credits the ring, or acknowledges, while it reads
                link.shut()  # (a closed socket answers its acks with a reset, and the reset
                # makes the receiver's kernel drop what it has not read yet)
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(linger):
                    await link.closed
            if not link.closed.done():
                link.transport.abort()

    def _flush_soon(self) -> None:
        self._scheduled = False
        self._flush()

    def _flush(self) -> None:
        link = self._link
        if link is not None:
            self._writer.flush(link.write, self._paused, link.ring)
            self._room.set()  # wakes `drain` and `flushed`, which recheck

    @staticmethod
    def _never() -> bool:
        return False

    def _acked(self, seq: int, dropped: int) -> None:
        retention = self._writer.retention
        if retention is not None:
            retention.ack(seq)
        self.dropped_remote += dropped  # the receiver's drops since its previous ack

    def _resume(self, link: Link) -> None:
        if link is self._link:
            self._flush()

    def _lost(self, link: Link) -> None:
        self._draining.discard(link)
        if link is self._link:
            self._link = None
            self._writer.drop_frame()  # the frame being written is lost with the link
            self._wake.set()

    async def _run(self) -> None:
        initial, cap = self.backoff
        delay = initial
        dropped = False
        while not self._closing:
            await self._settle()
            to = self.to
            hello = Hello(
                self.conn_id,
                self.in_port,
                self.from_,
                self.given,
                ack=self._offer(),
                type=self.type_id,
            )
            try:
                async with asyncio.timeout(self.hello_timeout):
                    link = await dial(
                        to,
                        hello,
                        self._resume,
                        self._lost,
                        shm_size=self.shm_size,
                        on_ack=self._acked,
                        auth=self.auth,
                        encrypt=getattr(self.policy, "encrypt", True),
                    )
            except (OSError, TimeoutError, FrameError, ValueError) as exc:
                self.last_error = f"{to}: {exc}"
                log.debug("data connection %s: dial failed: %s", self.conn_id, self.last_error)
                if isinstance(exc, FrameError) and exc.reason == "refused":
                    self.refusals.refused(exc.detail)
                self._wake.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(delay):
                        await self._wake.wait()  # a repoint or close cuts the wait short
                delay = next_backoff(delay, initial, cap)
                continue
            if self.to != to or self._closing:  # repointed while dialing: nothing written yet
                link.on_ack = None
                link.transport.abort()
                continue
            delay = initial
            self.refusals.through()
            if dropped:
                self.reconnects += 1
            self._adopt(link)
            self._wake.set()
            self._flush()
            while self._link is link:
                self._wake.clear()
                await self._wake.wait()
            dropped = self.to == to

    def _offer(self) -> AckOffer | None:
        """The hello's ack map: the first seq the next link carries (the oldest unacked)."""
        if self.window is None:
            return None
        retention = self._writer.retention
        first = retention.base if retention is not None else self._writer.seq + 1
        return AckOffer(self.session, first, drops=True)

    def _adopt(self, link: Link) -> None:
        """Make `link` the current one: replay what is unacknowledged, set up the window."""
        writer = self._writer
        writer.replay(link.write)
        if link.acks and self.window is not None:
            if writer.retention is None:
                writer.retention = Retention(*self.window, first_seq=writer.seq + 1)

            def paused() -> bool:
                return link.is_paused() or writer.window_full

            self._paused = paused
        else:
            writer.retention = None
            self._paused = link.is_paused
        self._link = link

    async def _settle(self) -> None:
        """Wait (at most `drain_timeout`) for repointed links to deliver their last acks."""
        if not self._draining:
            return
        waits = [asyncio.shield(link.closed) for link in self._draining]
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(self.drain_timeout):
                await asyncio.gather(*waits)
        for link in self._draining:
            if not link.closed.done():
                log.info("data connection %s: old link still open; aborted", self.conn_id)
                link.transport.abort()
        self._draining.clear()
