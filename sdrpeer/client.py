"""A small synchronous client for an agent's HTTP API (the CLI, the lab, the tools).

Finding the agent: `--api URL`, else `$SDRPEER_API`, else the lab file (first robot). The token:
`--token`, else `$SDRPEER_TOKEN`, else the lab robot whose API URL matches. Every failure is an
`ApiError` whose message names the agent and says what to do.

This module is what `sdrpeer members|status|instances` load besides the parser, so it stays
light. A JSON call is one HTTP/1.1 exchange on a plain socket (`_exchange`: the request with
`Connection: close`, the answer read to the end, its status, Content-Length or chunks): the
agent's API is a JSON API on loopback or the robots' network, and `http.client` would cost half of
such a command's CPU (it loads the `email` parser and `ssl`). An `https://` address goes through
`http.client`; the port tools' streams through urllib. The records are NamedTuples
(`dataclasses` loads `inspect`).
"""

from __future__ import annotations

import json
import socket
import time
import urllib.parse
from collections.abc import Callable, Iterable, Iterator, Mapping
from pathlib import Path
from typing import Any, NamedTuple, TypeVar

from sdrpeer.errors import ApiError, SdrpeerError

T = TypeVar("T")

DEFAULT_TIMEOUT = 5.0
LAB_DIR = Path(".sdrpeer-lab")
"""Where a client command looks for `lab.json` unless told (`sdrpeer.lab.files.DEFAULT_DIR`)."""


class AgentClient(NamedTuple):
    """Calls one agent's API at `base` (e.g. "http://127.0.0.1:8080")."""

    base: str
    token: str | None = None
    timeout: float = DEFAULT_TIMEOUT

    def get(self, path: str, **query: Any) -> Any:
        """GET `path` with query parameters; the decoded JSON answer."""
        if query:
            path = f"{path}?{urllib.parse.urlencode(query)}"
        return self.request("GET", path)

    def post(self, path: str, body: Any) -> Any:
        """POST a JSON body to `path` (with the token); the decoded JSON answer."""
        return self.request("POST", path, body)

    def request(self, method: str, path: str, body: Any = None) -> Any:
        """One HTTP call; raises ApiError with a message meant for a person."""
        url = urllib.parse.urlsplit(self.base.rstrip("/") + path)
        headers = {"Accept": "application/json"}
        data = None
        if body is not None:
            data = json.dumps(body).encode()
            headers["Content-Type"] = "application/json"
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        exchange = _exchange_tls if url.scheme == "https" else _exchange
        try:
            status, reason, raw = exchange(url, method, data, headers, self.timeout)
        except OSError as exc:  # refused, timed out, unknown host, reset
            raise ApiError(unreachable_message(self.base, exc)) from None
        except ValueError as exc:  # a bad port in the URL, an answer that is not HTTP
            raise ApiError(f"agent at {self.base}: {exc}") from None
        if not 200 <= status < 300:
            message = f"agent at {self.base} answered {status}: "
            raise ApiError(message + _error_text(raw, reason), status)
        try:
            return json.loads(raw) if raw else None
        except json.JSONDecodeError:
            raise ApiError(f"agent at {self.base} sent something that is not JSON") from None

    def stream(self, path: str, body: Any) -> Iterator[Any]:
        """POST a JSON body and read the answer as a stream of msgpack values, yielding each as
        it arrives (a port tap); no time limit while it lasts (the agent ends it)."""
        import msgpack  # noqa: PLC0415 - only the port tools read msgpack; the CLI starts light

        data = json.dumps(body).encode()
        headers = {"Content-Type": "application/json", "Accept": "application/x-msgpack"}
        with self._open("POST", path, data, headers, None) as response:
            unpacker = msgpack.Unpacker(raw=False, max_buffer_size=256 * 1024 * 1024)
            while chunk := response.read1(1 << 20):
                unpacker.feed(chunk)
                yield from unpacker

    def upload(self, path: str, chunks: Iterable[bytes]) -> Any:
        """POST a body sent in chunks as they are produced (chunked transfer encoding; a port
        feed); the decoded JSON answer."""
        headers = {"Content-Type": "application/x-msgpack", "Accept": "application/json"}
        with self._open("POST", path, chunks, headers, None) as response:
            raw = response.read()
        try:
            return json.loads(raw) if raw else None
        except json.JSONDecodeError:
            raise ApiError(f"agent at {self.base} sent something that is not JSON") from None

    def _open(
        self,
        method: str,
        path: str,
        data: bytes | Iterable[bytes],
        headers: dict[str, str],
        timeout: float | None,
    ) -> Any:
        import urllib.error  # noqa: PLC0415 - streams (chunked uploads) only: the CLI starts light
        import urllib.request  # noqa: PLC0415

        url = self.base.rstrip("/") + path
        if self.token:
            headers["Authorization"] = f"Bearer {self.token}"
        req = urllib.request.Request(url, data=data, headers=headers, method=method)
        try:
            return urllib.request.urlopen(req, timeout=timeout)
        except urllib.error.HTTPError as exc:
            try:
                raw = exc.read()
            except OSError:
                raw = b""
            message = f"agent at {self.base} answered {exc.code}: {_error_text(raw, exc.reason)}"
            raise ApiError(message, exc.code) from None
        except urllib.error.URLError as exc:
            raise ApiError(unreachable_message(self.base, exc.reason)) from None
        except (TimeoutError, ConnectionError) as exc:
            raise ApiError(unreachable_message(self.base, exc)) from None

    def members(self) -> list[dict[str, Any]]:
        """GET /v1/members."""
        return list(self.get("/v1/members"))

    def agent(self) -> dict[str, Any]:
        """GET /v1/agent."""
        return dict(self.get("/v1/agent"))

    def events(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        """GET /v1/events?since=&limit=."""
        return list(self.get("/v1/events", since=since, limit=limit))


MAX_ANSWER = 256 * 1024 * 1024
"""Bytes of an answer read at most (a status of a large fleet is megabytes, not more)."""


def _exchange(
    url: urllib.parse.SplitResult,
    method: str,
    data: bytes | None,
    headers: dict[str, str],
    timeout: float,
) -> tuple[int, str, bytes]:
    """One HTTP/1.1 request on its own connection, `Connection: close`, and the answer read to
    its end: (status, reason, body). OSError when the agent cannot be reached, ValueError when
    what comes back is not an HTTP answer."""
    target = (url.path or "/") + (f"?{url.query}" if url.query else "")
    lines = [f"{method} {target} HTTP/1.1", f"Host: {url.netloc}", "Connection: close"]
    lines += [f"{k}: {v}" for k, v in headers.items()]
    if data is not None:
        lines.append(f"Content-Length: {len(data)}")
    request = ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + (data or b"")
    chunks: list[bytes] = []
    size = 0
    with socket.create_connection((url.hostname or "", url.port or 80), timeout) as sock:
        sock.sendall(request)
        while chunk := sock.recv(1 << 16):
            chunks.append(chunk)
            size += len(chunk)
            if size > MAX_ANSWER:
                raise ValueError(f"answered more than {MAX_ANSWER} bytes")
    head, sep, body = b"".join(chunks).partition(b"\r\n\r\n")
    status_line, *fields = head.decode("latin-1").split("\r\n")
    version, _, rest = status_line.partition(" ")
    code, _, reason = rest.partition(" ")
    if not sep or not version.startswith("HTTP/") or not code.isdigit():
        raise ValueError(f"the answer is not HTTP: {status_line[:80]!r}")
    header = {k.strip().lower(): v.strip() for k, _, v in (f.partition(":") for f in fields)}
    if header.get("transfer-encoding", "").lower() == "chunked":
        body = _dechunk(body)
    elif header.get("content-length", "").isdigit():
        body = body[: int(header["content-length"])]
    return int(code), reason, body


def _dechunk(body: bytes) -> bytes:
    """The data of a chunked body (RFC 9112, 7.1); ValueError when it is cut or malformed."""
    out: list[bytes] = []
    at = 0
    while True:
        end = body.find(b"\r\n", at)
        if end < 0:
            raise ValueError("a chunked answer ended early")
        size = int(body[at:end].split(b";")[0], 16)
        if size == 0:
            return b"".join(out)
        start = end + 2
        if start + size > len(body):
            raise ValueError("a chunked answer ended early")
        out.append(body[start : start + size])
        at = start + size + 2


def _exchange_tls(
    url: urllib.parse.SplitResult,
    method: str,
    data: bytes | None,
    headers: dict[str, str],
    timeout: float,
) -> tuple[int, str, bytes]:
    """`_exchange` for an https:// agent, with `http.client` (TLS, certificates)."""
    import http.client  # noqa: PLC0415 - only an https:// address needs it

    target = (url.path or "/") + (f"?{url.query}" if url.query else "")
    conn = http.client.HTTPSConnection(url.hostname or "", url.port, timeout=timeout)
    try:
        conn.request(method, target, data, headers)
        response = conn.getresponse()
        return response.status, response.reason, response.read()
    except http.client.HTTPException as exc:
        raise ValueError(f"the answer is not HTTP: {exc}") from None
    finally:
        conn.close()


def _error_text(raw: bytes, reason: object) -> str:
    """What an error answer says: its JSON `error`, else the HTTP reason."""
    try:
        body = json.loads(raw or b"{}")
    except (json.JSONDecodeError, UnicodeDecodeError):
        body = {}
    if isinstance(body, dict) and "error" in body:
        return str(body["error"])
    return str(reason)


def unreachable_message(base: str, reason: object) -> str:
    """'cannot reach agent at URL: connection refused; is it running? (sdrpeer lab up)'."""
    if isinstance(reason, ConnectionRefusedError):
        why = "connection refused"
    elif isinstance(reason, TimeoutError | socket.timeout):
        why = "timed out"
    elif isinstance(reason, socket.gaierror):
        why = f"unknown host ({reason.strerror})"
    else:
        why = str(getattr(reason, "strerror", None) or reason)
    return f"cannot reach agent at {base}: {why}; is it running? (sdrpeer lab up)"


def normalize_api(text: str) -> str:
    """'127.0.0.1:8080' or 'http://127.0.0.1:8080/' -> 'http://127.0.0.1:8080'."""
    text = text.strip().rstrip("/")
    return text if "://" in text else f"http://{text}"


class Endpoint(NamedTuple):
    """Where the CLI sends its calls, and how it found out (for error messages)."""

    api: str
    token: str | None
    source: str


def read_lab_robots(lab_dir: Path) -> list[dict[str, Any]]:
    """The robots listed in `lab_dir/lab.json`, or [] when there is no lab file."""
    path = lab_dir / "lab.json"
    try:
        data = json.loads(path.read_text())
    except FileNotFoundError:
        return []
    except (OSError, json.JSONDecodeError) as exc:
        raise ApiError(f"{path}: cannot read the lab file: {exc}") from None
    robots = data.get("robots") if isinstance(data, dict) else None
    return [r for r in robots or [] if isinstance(r, dict)]


def resolve_endpoint(
    api: str | None, token: str | None, lab_dir: Path, env: Mapping[str, str]
) -> Endpoint:
    """Find the agent to talk to: flag, then $SDRPEER_API, then the lab file's first robot."""
    robots = read_lab_robots(lab_dir)
    token = token or env.get("SDRPEER_TOKEN") or None
    if api or env.get("SDRPEER_API"):
        source = "--api" if api else "$SDRPEER_API"
        base = normalize_api(api or env["SDRPEER_API"])
        if token is None:
            token = next((r.get("token") for r in robots if r.get("api") == base), None)
        return Endpoint(base, token, source)
    live = [r for r in robots if r.get("api")]
    if not live:
        raise ApiError(
            f"no agent to talk to: pass --api URL, set SDRPEER_API, or start a lab "
            f"(sdrpeer lab up; looked for {lab_dir / 'lab.json'})"
        )
    return Endpoint(str(live[0]["api"]), token or live[0].get("token"), str(lab_dir / "lab.json"))


def wait_for(
    probe: Callable[[], T],
    ok: Callable[[T], bool],
    what: str,
    timeout: float,
    poll: float = 0.02,
) -> T:
    """Call `probe()` every `poll` s until `ok(value)`; an ApiError counts as not yet.
    After `timeout` s: SdrpeerError naming `what` and the last answer (labs, demo, benchmarks)."""
    deadline = time.monotonic() + timeout
    last: Any = None
    while time.monotonic() < deadline:
        try:
            value = probe()
        except ApiError as e:
            last = str(e)
        else:
            if ok(value):
                return value
            last = value
        time.sleep(poll)
    raise SdrpeerError(f"timed out after {timeout:g} s waiting for {what}; last: {last!r:.400}")


ELECTION_WAIT = 15.0
"""Seconds a state-changing call waits at most for an allocator to be elected."""


def post_when_elected(client: AgentClient, path: str, body: Any, timeout: float) -> Any:
    """POST, retrying while the agents answer 503 (no allocator yet, or the allocator hears a
    robot whose record has not arrived), for at most `timeout` s."""
    deadline = time.monotonic() + min(timeout, ELECTION_WAIT)
    while True:
        try:
            return client.post(path, body)
        except ApiError as e:
            if e.status != 503 or time.monotonic() > deadline:
                raise
        time.sleep(0.2)
