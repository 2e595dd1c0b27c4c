"""Encrypted data streams: AES-256-GCM records on an authenticated TCP connection.

How it works (docs/protocol.md section 2, "Encryption"): once both ends of a TCP data connection
proved they hold a data key (sdrpeer.dataplane.auth) and both said ``"enc": true``, everything
after the sender's proof travels in *records*, both ways (frames one way; acknowledgements the
other): a 4-byte big-endian length, then AES-256-GCM of the bytes the writer handed the socket in
one write, with its 16-byte tag. Each direction has its own key, derived with HKDF-SHA256 from the
data key both proofs used, salted with both handshake nonces (fresh per connection) and bound to
the connection's names, so no two connections or directions share a key; the nonce is a counter
of the records sent that way (never reused under a key). A record that does not verify, arrives
out of order, or is longer than `max_record` breaks the connection (FrameError): an on-path
attacker can cut it, not read or alter it. A writer joins many small frames into one write, so
small frames cost one seal per batch, not one per frame.

`cryptography` (OpenSSL) is imported only when a stream is encrypted: a host that only talks over
Unix sockets or shared memory (same robot) stays without it.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any, Final

from sdrpeer.errors import FrameError

__all__ = ["Opener", "Sealer", "sealed_writer"]

LENGTH: Final = 4
TAG: Final = 16
OVERHEAD: Final = LENGTH + TAG
"""Bytes a record adds to the bytes it carries."""
_LEN: Final = struct.Struct(">I")


def _cipher(key: bytes) -> Any:
    from cryptography.hazmat.primitives.ciphers.aead import AESGCM  # noqa: PLC0415

    return AESGCM(key)


class Sealer:
    """One direction's sending side: bytes in, records out."""

    __slots__ = ("_encrypt", "_n")

    def __init__(self, key: bytes) -> None:
        self._encrypt = _cipher(key).encrypt
        self._n = 0

    def seal(self, data: bytes | bytearray | memoryview) -> tuple[bytes, bytes]:
        """One record carrying `data`: its length prefix and its sealed bytes (written one
        after the other: joining them would copy the sealed bytes once more)."""
        self._n += 1
        sealed: bytes = self._encrypt(self._n.to_bytes(12, "big"), data, None)
        return _LEN.pack(len(sealed)), sealed


RECORD: Final = 256 * 1024
"""Longest record sealed: a big write is cut into records of this size, so that the receiver
decrypts the first while the next travels (one 1 MiB record would be decrypted only whole)."""
SMALL_RECORD: Final = 16 * 1024
"""Records up to this size go out as one write (length and bytes joined: one syscall)."""


def sealed_writer(
    key: bytes, write: Callable[[bytes], object]
) -> Callable[[bytes | bytearray | memoryview], None]:
    """A `write` that seals what it is given into records (of at most `RECORD` bytes)."""
    seal = Sealer(key).seal

    def sealed(data: bytes | bytearray | memoryview) -> None:
        if len(data) <= SMALL_RECORD:
            head, body = seal(data)
            write(head + body)
            return
        view = memoryview(data)
        for start in range(0, len(view), RECORD):
            head, body = seal(view[start : start + RECORD])
            write(head)  # two writes: joining would copy the sealed bytes once more
            write(body)

    return sealed


class Opener:
    """One direction's receiving side: records in (in any pieces), the bytes they carry out.

    The socket may read straight into `buffer()` (then `received(n)`); `next_record()` gives the
    next complete record, which `open_into` decrypts into the caller's buffer (no copy on the
    way) or `open_record` into new bytes. `open(data)` does all of that for bytes at hand."""

    __slots__ = (
        "_array",
        "_decrypt",
        "_decrypt_into",
        "_end",
        "_invalid",
        "_n",
        "_start",
        "_view",
        "max_record",
    )

    def __init__(self, key: bytes, max_record: int, read_size: int = 1024 * 1024) -> None:
        from cryptography.exceptions import InvalidTag  # noqa: PLC0415

        cipher = _cipher(key)
        self._decrypt = cipher.decrypt
        self._decrypt_into = cipher.decrypt_into
        self._invalid = InvalidTag
        self._n = 0
        self._array = bytearray(read_size)
        self._view = memoryview(self._array)
        self._start = 0  # first byte of the next record
        self._end = 0  # end of the bytes received
        self.max_record = max_record
        """Longest record accepted (ciphertext and tag), in bytes."""

    def buffer(self) -> memoryview:
        """Free space to receive into (never empty)."""
        if self._end == len(self._array):
            self._make_room(self._end - self._start + 1)
        return self._view[self._end :]

    def received(self, nbytes: int) -> None:
        """`nbytes` were written into the start of the last `buffer()`."""
        self._end += nbytes

    def next_record(self) -> memoryview | None:
        """The next complete record's ciphertext and tag (valid until the next call), or None
        until it has all arrived; FrameError when its length is impossible."""
        start, end = self._start, self._end
        if end - start < LENGTH:
            self._compact()
            return None
        (size,) = _LEN.unpack_from(self._array, start)
        if size < TAG or size > self.max_record:
            raise FrameError("malformed", f"encrypted record of {size} bytes")
        if end - start - LENGTH < size:
            self._make_room(LENGTH + size)
            return None
        self._start = start + LENGTH + size
        return self._view[start + LENGTH : start + LENGTH + size]

    def open_into(self, record: memoryview, out: memoryview) -> None:
        """Decrypt `record` into `out` (exactly its size: the record's less the tag)."""
        self._n += 1
        try:
            self._decrypt_into(self._n.to_bytes(12, "big"), record, None, out)
        except self._invalid:
            raise FrameError("malformed", "an encrypted record does not verify") from None

    def open_record(self, record: memoryview) -> bytes:
        """`record` decrypted into new bytes."""
        self._n += 1
        try:
            plain: bytes = self._decrypt(self._n.to_bytes(12, "big"), record, None)
        except self._invalid:
            raise FrameError("malformed", "an encrypted record does not verify") from None
        return plain

    def open(self, data: bytes | bytearray | memoryview) -> list[bytes]:
        """The bytes of every record completed by `data`, in order; FrameError when one is too
        long or does not verify (the stream is then broken)."""
        view = memoryview(data)
        out: list[bytes] = []
        while view:
            space = self.buffer()
            n = min(len(space), len(view))
            space[:n] = view[:n]
            self.received(n)
            view = view[n:]
            while (record := self.next_record()) is not None:
                out.append(self.open_record(record))
        return out

    def _compact(self) -> None:
        """Move what is left of the next record to the front once the buffer ran out."""
        if self._start == self._end:
            self._start = self._end = 0
        elif len(self._array) - self._start < LENGTH + TAG + 16:
            kept = self._end - self._start
            self._view[:kept] = self._view[self._start : self._end]
            self._start, self._end = 0, kept

    def _make_room(self, total: int) -> None:
        """Make sure a record of `total` bytes (length included) fits from `_start` on."""
        if len(self._array) - self._start >= total:
            return
        kept = self._end - self._start
        if len(self._array) < total:
            array = bytearray(max(total, len(self._array)))
            array[:kept] = self._view[self._start : self._end]
            self._array, self._view = array, memoryview(array)
        else:
            self._view[:kept] = self._view[self._start : self._end]
        self._start, self._end = 0, kept
