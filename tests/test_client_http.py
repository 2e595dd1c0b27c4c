"""`sdrpeer.client`'s own HTTP/1.1 exchange against a real socket: what it sends, what it reads."""

from __future__ import annotations

import socket
import threading
from collections.abc import Iterator

import pytest

from sdrpeer.client import AgentClient
from sdrpeer.errors import ApiError


class OneShotServer:
    """A loopback TCP server that answers `calls` connections with `answer`, keeping what came."""

    def __init__(self, answer: bytes, calls: int) -> None:
        self.answer = answer
        self.calls = calls
        self.received: list[bytes] = []
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.sock.settimeout(10.0)
        self.thread = threading.Thread(target=self._serve, daemon=True)
        self.thread.start()

    @property
    def base(self) -> str:
        """The server's URL."""
        return f"http://127.0.0.1:{self.sock.getsockname()[1]}"

    def _serve(self) -> None:
        for _ in range(self.calls):
            try:
                conn, _ = self.sock.accept()
            except OSError:
                return
            with conn:
                conn.settimeout(10.0)
                data = b""
                while b"\r\n\r\n" not in data:
                    data += conn.recv(4096)
                head, _, body = data.partition(b"\r\n\r\n")
                for line in head.split(b"\r\n"):
                    if line.lower().startswith(b"content-length:"):
                        want = int(line.split(b":")[1])
                        while len(body) < want:
                            body += conn.recv(4096)
                self.received.append(head + b"\r\n\r\n" + body)
                conn.sendall(self.answer)

    def close(self) -> None:
        """Stop accepting."""
        self.sock.close()
        self.thread.join(timeout=10)


@pytest.fixture
def serve() -> Iterator[list[OneShotServer]]:
    servers: list[OneShotServer] = []
    yield servers
    for server in servers:
        server.close()


def server(servers: list[OneShotServer], answer: bytes, calls: int = 1) -> OneShotServer:
    s = OneShotServer(answer, calls)
    servers.append(s)
    return s


def test_a_get_and_a_post_are_one_http11_request_each(serve: list[OneShotServer]) -> None:
    s = server(serve, b'HTTP/1.1 200 OK\r\nContent-Length: 11\r\n\r\n{"ok": 1}\n\nEXTRA', calls=2)
    client = AgentClient(s.base, "tok")
    assert client.get("/v1/events", since=3) == {"ok": 1}  # Content-Length bounds the body
    assert client.post("/v1/robot", {"battery": "30%"}) == {"ok": 1}
    get, post = (r.decode() for r in s.received)
    assert get.startswith("GET /v1/events?since=3 HTTP/1.1\r\n")
    assert f"Host: {s.base[7:]}\r\n" in get
    assert "Connection: close\r\n" in get
    assert "Authorization: Bearer tok\r\n" in get
    assert post.startswith("POST /v1/robot HTTP/1.1\r\n")
    assert "Content-Type: application/json\r\n" in post
    assert "Content-Length: 18\r\n" in post
    assert post.endswith('\r\n\r\n{"battery": "30%"}')


def test_a_chunked_answer_is_put_together(serve: list[OneShotServer]) -> None:
    s = server(
        serve,
        b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n"
        b"4\r\n[1, \r\n3;ext=1\r\n2, \r\n2\r\n3]\r\n0\r\n\r\n",
    )
    assert AgentClient(s.base).get("/v1/members") == [1, 2, 3]


def test_an_error_answer_says_the_agents_words(serve: list[OneShotServer]) -> None:
    body = b'{"error": "missing or wrong token"}'
    s = server(
        serve,
        b"HTTP/1.1 401 Unauthorized\r\nContent-Length: %d\r\n\r\n%s" % (len(body), body),
    )
    with pytest.raises(ApiError) as info:
        AgentClient(s.base).post("/v1/deploy", {})
    assert str(info.value) == f"agent at {s.base} answered 401: missing or wrong token"
    assert info.value.status == 401


@pytest.mark.parametrize(
    ("answer", "message"),
    [
        (b"SSH-2.0-OpenSSH_9.2\r\n", "the answer is not HTTP: 'SSH-2.0-OpenSSH_9.2'"),
        (
            b"HTTP/1.1 200 OK\r\nTransfer-Encoding: chunked\r\n\r\n9\r\n[1, 2",
            "a chunked answer ended early",
        ),
        (b"", "the answer is not HTTP: ''"),
    ],
)
def test_an_answer_that_is_not_http_is_an_api_error(
    serve: list[OneShotServer], answer: bytes, message: str
) -> None:
    s = server(serve, answer)
    with pytest.raises(ApiError) as info:
        AgentClient(s.base).get("/v1/status")
    assert str(info.value) == f"agent at {s.base}: {message}"
