"""The SDK honours ``Retry-After``: a GET answered 429 or 503 is sent again after the delay the header gives
(seconds or an HTTP date), a bounded number of times within a bounded total wait; then, and for a POST at once,
the error carries ``retry_after``.  Against real HTTP servers on 127.0.0.1: a tiny scripted one, and a
`twb server` whose limit on unknown tokens answers 429."""

from __future__ import annotations

import contextlib
import email.utils
import json
import threading
import time
from datetime import datetime, timezone
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any, Iterator

import pytest

from client_sdk import AsyncClient, Client, RateLimited, Unauthorized, Unavailable
from client_sdk._base import retry_after

USER = {"id": 1, "name": "ada", "is_admin": False, "created_at": "2026-01-02T03:04:05Z"}
Answer = tuple[int, dict[str, str], Any]


@contextlib.contextmanager
def scripted(*answers: Answer) -> Iterator[tuple[str, list[tuple[float, str, str]]]]:
    """An HTTP server on 127.0.0.1 answering the n-th request with ``answers[n]`` (the last one repeats):
    its URL and, per request, when it came (monotonic s), its method and path."""
    seen: list[tuple[float, str, str]] = []

    class Handler(BaseHTTPRequestHandler):
        def answer(self) -> None:
            self.rfile.read(int(self.headers.get("Content-Length") or 0))
            seen.append((time.monotonic(), self.command, self.path))
            status, headers, body = answers[min(len(seen), len(answers)) - 1]
            data = json.dumps(body).encode()
            self.send_response(status)
            for name, value in {**headers, "Content-Type": "application/json",
                                "Content-Length": str(len(data))}.items():
                self.send_header(name, value() if callable(value) else value)
            self.end_headers()
            self.wfile.write(data)

        do_GET = do_POST = answer

        def log_message(self, *args: Any) -> None:
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    try:
        yield f"http://127.0.0.1:{server.server_port}", seen
    finally:
        server.shutdown()
        server.server_close()
        thread.join(5)


def in_two_seconds() -> str:
    """An HTTP date 2 s ahead, whole seconds: a wait of more than 1 s and at most 2 s."""
    return email.utils.formatdate(time.time() + 2, usegmt=True)


def gaps(seen: list[tuple[float, str, str]]) -> list[float]:
    return [b[0] - a[0] for a, b in zip(seen, seen[1:])]


def test_a_get_is_sent_again_after_the_seconds_or_the_date_retry_after_gives():
    with scripted((429, {"Retry-After": "1"}, {"detail": "slow down"}),
                  (503, {"Retry-After": in_two_seconds}, {"detail": "the database is unreachable"}),
                  (200, {}, USER)) as (url, seen):
        with Client(url, "tok") as c:
            assert c.me().name == "ada"
    assert [(m, p) for _, m, p in seen] == [("GET", "/api/v1/users/me")] * 3
    first, second = gaps(seen)
    assert 1.0 <= first < 10 and 0.9 <= second < 10


async def test_the_async_client_waits_too():
    with scripted((429, {"Retry-After": "1"}, {"detail": "slow down"}), (200, {}, {"data": [], "count": 0})) as (url, seen):
        async with AsyncClient(url, "tok") as c:
            assert (await c.list_programs()).count == 0
    assert len(seen) == 2 and 1.0 <= gaps(seen)[0] < 10


def test_it_gives_up_after_max_retries_with_retry_after():
    with scripted((429, {"Retry-After": "0"}, {"detail": "slow down"})) as (url, seen):
        with Client(url, "tok", max_retries=2) as c, pytest.raises(RateLimited, match="^429 .*: slow down$") as e:
            c.list_robots()
    assert len(seen) == 3 and e.value.retry_after == 0.0 and e.value.status == 429


def test_the_waits_stay_within_max_retry_wait():
    with scripted((503, {"Retry-After": "120"}, {"detail": "down"})) as (url, seen):
        t0 = time.monotonic()
        with Client(url, "tok") as c, pytest.raises(Unavailable) as e:  # 120 s > 30 s: at once
            c.get_run(1)
    assert len(seen) == 1 and e.value.retry_after == 120.0 and time.monotonic() - t0 < 5
    with scripted((429, {"Retry-After": "1"}, {"detail": "slow down"})) as (url, seen):
        with Client(url, "tok", max_retries=5, max_retry_wait=1.5) as c, pytest.raises(RateLimited):
            c.get_run(1)
    assert len(seen) == 2  # 1 s waited; another 1 s would make 2 s > 1.5 s


def test_a_post_is_not_sent_again_nor_an_answer_without_retry_after():
    with scripted((429, {"Retry-After": "0"}, {"detail": "slow down"})) as (url, seen):
        with Client(url, "tok") as c, pytest.raises(RateLimited) as e:
            c.submit("room", start=[0.3, 0.3], goal=[1.5, 1.5])
    assert [m for _, m, _ in seen] == ["POST"] and e.value.retry_after == 0.0
    with scripted((429, {}, {"detail": "you already have 200 queued experiments (limit 200)"})) as (url, seen):
        with Client(url, "tok") as c, pytest.raises(RateLimited) as e:
            c.list_experiments()
    assert len(seen) == 1 and e.value.retry_after is None


@pytest.mark.parametrize("value,seconds", [
    ("7", 7.0), (" 0 ", 0.0), ("Thu, 01 Jan 2026 00:00:07 GMT", 7.0), ("Thursday, 01-Jan-26 00:00:07 GMT", 7.0),
    ("Wed, 21 Oct 2015 07:28:00 GMT", 0.0), (None, None), ("soon", None), ("-3", None), ("1.5", None), ("²", None)])
def test_retry_after_values(value, seconds):
    assert retry_after(value, now=datetime(2026, 1, 1, tzinfo=timezone.utc)) == seconds


@pytest.fixture(scope="module")
def strict_server(testbeds):
    """`twb server` that answers 429 after one unknown token per minute from a client (its own)."""
    yield from testbeds.own("server", env={"TWB_AUTH_FAILURES_PER_MINUTE": "1"})


def test_the_testbeds_limit_on_unknown_tokens_is_raised_with_its_retry_after(strict_server):
    with Client(strict_server.url, "not-a-token") as c:
        with pytest.raises(Unauthorized):
            c.me()
        t0 = time.monotonic()
        with pytest.raises(RateLimited, match="Too many unknown tokens") as e:  # Retry-After ~60 s > 30 s
            c.me()
    assert 50 < e.value.retry_after <= 60 and time.monotonic() - t0 < 5
