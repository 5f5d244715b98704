"""Both transports run over TLS (wss://, tls://) with a certificate and key."""

import shutil
import subprocess

import pytest
from astcom_helpers import PASSWORDS, run, served

from astcom_client import Client, ConnectionClosed

pytestmark = pytest.mark.skipif(shutil.which("openssl") is None, reason="needs the openssl tool")


@pytest.fixture(scope="module")
def certificate(tmp_path_factory) -> tuple[str, str]:
    """Make a self-signed certificate for 127.0.0.1 (it is its own authority)."""
    folder = tmp_path_factory.mktemp("tls")
    cert, key = str(folder / "cert.pem"), str(folder / "key.pem")
    subprocess.run(["openssl", "req", "-x509", "-newkey", "ec", "-pkeyopt",
                    "ec_paramgen_curve:prime256v1", "-nodes", "-keyout", key, "-out", cert,
                    "-days", "2", "-subj", "/CN=localhost",
                    "-addext", "subjectAltName=IP:127.0.0.1,DNS:localhost"],
                   check=True, capture_output=True)
    return cert, key


@pytest.mark.parametrize("scheme", ["wss", "tls"])
def test_a_client_trusting_the_certificate_talks_over_tls(scheme: str, certificate) -> None:
    cert, key = certificate

    async def main() -> None:
        async with served(f"{scheme}://127.0.0.1:0", realtime=True, certfile=cert,
                          keyfile=key) as (_, _, url):
            client = await Client.connect(url, password=PASSWORDS["operator"], cafile=cert)
            assert await client.invoke("math.add", 2.0, 2.0) == 4.0
            stream = await client.stream(["counter"], rate_hz=100)
            packet = await stream.get(timeout_s=5.0)
            assert packet.n > 0 and packet.lost == 0
            await client.close()
    run(main())


@pytest.mark.parametrize("scheme", ["wss", "tls"])
def test_a_client_that_cannot_verify_the_certificate_is_refused(scheme: str, certificate) -> None:
    cert, key = certificate

    async def main() -> None:
        async with served(f"{scheme}://127.0.0.1:0", certfile=cert, keyfile=key) as (_, _, url):
            with pytest.raises(ConnectionClosed, match="cannot connect"):
                await Client.connect(url, password=PASSWORDS["operator"], timeout_s=5.0)
    run(main())


def test_serving_tls_without_a_certificate_is_refused_with_what_is_needed() -> None:
    async def main() -> None:
        async with served() as (_, endpoint, _):
            with pytest.raises(ValueError, match="certfile"):
                await endpoint.serve("wss://127.0.0.1:0")
    run(main())
