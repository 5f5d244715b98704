"""Browser pages from other sites cannot open a WebSocket to an endpoint (cross-site hijacking)."""

import pytest
from astcom_helpers import run, served
from websockets.asyncio.client import connect
from websockets.exceptions import InvalidStatus

from astcom_client import Client, EndpointConfig

LOOPBACK_PAGES = ["http://127.0.0.1:8080", "http://localhost:5173", "http://[::1]:8080",
                  "https://localhost", "http://127.0.0.1"]
FOREIGN_PAGES = ["https://evil.example", "http://192.168.1.20:8080", "null",
                 "http://127.0.0.1.evil.example", "http://localhost.evil.example:8080",
                 "file://", "chrome-extension://abcdef"]


async def handshake(url: str, origin: str | None) -> tuple[int, str]:
    """Open a WebSocket with this Origin header; return (HTTP status, body)."""
    try:
        ws = await connect(url, origin=origin, proxy=None, open_timeout=5)
    except InvalidStatus as exc:
        return exc.response.status_code, exc.response.body.decode()
    await ws.close()
    return 101, ""


def test_pages_from_other_sites_are_refused_with_403_and_a_reason() -> None:
    async def main() -> None:
        async with served("ws://127.0.0.1:0", passwords=None) as (_, endpoint, url):
            for origin in FOREIGN_PAGES:
                status, body = await handshake(url, origin)
                assert status == 403, origin
                assert "refused" in body and "allowed_origins" in body, body
            assert endpoint.stats()["clients"] == 0
    run(main())


def test_loopback_pages_and_clients_without_origin_are_accepted_by_default() -> None:
    async def main() -> None:
        async with served("ws://127.0.0.1:0", passwords=None) as (_, _, url):
            for origin in [*LOOPBACK_PAGES, None]:
                assert (await handshake(url, origin))[0] == 101, origin
            async with await Client.connect(url) as client:  # the Python client sends no Origin
                assert "counter" in await client.read(["counter"])
    run(main())


def test_an_explicit_list_replaces_the_loopback_default() -> None:
    async def main() -> None:
        pages = ["https://panel.example.org", "http://Ops.Example:8080/"]
        async with served("ws://127.0.0.1:0", allowed_origins=pages) as (_, _, url):
            assert (await handshake(url, "https://panel.example.org:443"))[0] == 101
            assert (await handshake(url, "http://ops.example:8080"))[0] == 101
            assert (await handshake(url, None))[0] == 101
            status, body = await handshake(url, "http://127.0.0.1:8080")
            assert status == 403 and "panel.example.org" in body
            assert (await handshake(url, "http://ops.example:8081"))[0] == 403
        both = ["loopback", "https://panel.example.org"]
        async with served("ws://127.0.0.1:0", allowed_origins=both) as (_, _, url):
            assert (await handshake(url, "http://[::1]:9000"))[0] == 101
            assert (await handshake(url, "https://panel.example.org"))[0] == 101
            assert (await handshake(url, "https://evil.example"))[0] == 403
    run(main())


def test_a_star_accepts_pages_from_any_site() -> None:
    async def main() -> None:
        async with served("ws://127.0.0.1:0", allowed_origins=["*"]) as (_, _, url):
            for origin in FOREIGN_PAGES:
                assert (await handshake(url, origin))[0] == 101, origin
    run(main())


@pytest.mark.parametrize("bad", [["127.0.0.1:8080"], ["http://host/path"], ["ws://host"], "*", [3]])
def test_a_malformed_allowed_origins_entry_is_refused_when_configuring(bad) -> None:
    with pytest.raises(ValueError, match="allowed_origins"):
        EndpointConfig(allowed_origins=bad)
