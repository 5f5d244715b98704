"""The Alpaca protocol rules as ConformU checks them, over raw HTTP; discovery; the Sun zone."""

from __future__ import annotations

import json
import shutil
import socket
import subprocess
import sys
import textwrap
import urllib.error
import urllib.parse
import urllib.request

import pytest

from virtualstar.alpaca.protocol import (
    ACTION_NOT_IMPLEMENTED,
    INVALID_OPERATION,
    INVALID_VALUE,
    INVALID_WHILE_PARKED,
    NOT_CONNECTED,
    NOT_IMPLEMENTED,
    VALUE_NOT_SET,
)


def call(rig, method: str, member: str, params: dict | None = None, *, device: str = "telescope/0",
         headers: dict | None = None) -> tuple[int, object]:
    """One request; return (HTTP status, JSON reply or text body)."""
    data = None
    url = f"http://{rig.address}/api/v1/{device}/{member}"
    query = urllib.parse.urlencode(params or {})
    if method == "GET":
        url += f"?{query}" if query else ""
    else:
        data = query.encode()
    req = urllib.request.Request(url, data=data, method=method, headers=headers or {})
    if data is not None:
        req.add_header("Content-Type", "application/x-www-form-urlencoded")
    try:
        with urllib.request.urlopen(req, timeout=60) as resp:
            return resp.status, json.loads(resp.read())
    except urllib.error.HTTPError as exc:
        return exc.code, exc.read().decode()


def test_transaction_ids_are_echoed_and_counted_and_get_names_ignore_case(night):
    s1, r1 = call(night, "GET", "name", {"ClientID": 7, "ClientTransactionID": 41})
    s2, r2 = call(night, "GET", "name", {"clientid": 7, "CLIENTTRANSACTIONID": 42})
    assert s1 == s2 == 200
    assert (r1["ClientTransactionID"], r2["ClientTransactionID"]) == (41, 42)
    assert 1 <= r1["ServerTransactionID"] < r2["ServerTransactionID"]
    assert r1["ErrorNumber"] == 0 and r1["ErrorMessage"] == "" and r1["Value"] == "VirtualStar"
    _s, r3 = call(night, "GET", "name")
    assert r3["ClientTransactionID"] == 0
    status, reply = call(night, "PUT", "connected", {"Connected": "true", "ClientID": 7,
                                                     "ClientTransactionID": 43})
    assert status == 200 and reply["ErrorNumber"] == 0 and reply["ClientTransactionID"] == 43
    assert call(night, "GET", "targetdeclination", {"CLIENTID": 3})[0] == 200


def test_put_parameter_names_are_exact_as_conformu_checks(night):
    call(night, "PUT", "connected", {"Connected": "True"})
    status, body = call(night, "PUT", "targetdeclination", {"TARGETDECLINATION": "12.5"})
    assert status == 400 and "TargetDeclination" in body and "case-sensitive" in body
    status, reply = call(night, "PUT", "targetdeclination", {"TargetDeclination": "12.5",
                                                             "clienttransactionid": "77"})
    assert status == 200 and reply["ErrorNumber"] == 0
    assert reply["ClientTransactionID"] == 0  # a mis-cased id in a PUT is no id
    assert call(night, "GET", "targetdeclination")[1]["Value"] == 12.5


@pytest.mark.parametrize("bad", ["-1", "abc", "4294967296", "1.5", "", " 5"])
def test_a_bad_client_id_or_transaction_id_is_http_400(night, bad):
    for name in ("ClientID", "ClientTransactionID"):
        status, body = call(night, "GET", "name", {name: bad})
        assert status == 400 and name in body


def test_unknown_devices_and_members_are_404_and_wrong_methods_405(night):
    assert call(night, "GET", "name", device="telescope/1")[0] == 404
    assert call(night, "GET", "name", device="camera/0")[0] == 404
    assert call(night, "GET", "frobnicate")[0] == 404
    assert call(night, "PUT", "altitude")[0] == 405


def test_unreadable_values_are_400_and_out_of_range_values_are_invalid_value(night):
    call(night, "PUT", "connected", {"Connected": "True"})
    status, body = call(night, "PUT", "targetrightascension", {"TargetRightAscension": "noon"})
    assert status == 400 and "TargetRightAscension" in body
    status, body = call(night, "PUT", "slewtocoordinatesasync", {"RightAscension": "1"})
    assert status == 400 and "Declination" in body and "missing" in body
    status, body = call(night, "PUT", "connected", {"Connected": "yes"})
    assert status == 400
    status, reply = call(night, "PUT", "targetrightascension", {"TargetRightAscension": "25"})
    assert status == 200 and reply["ErrorNumber"] == INVALID_VALUE and "0 <= RA < 24" in \
        reply["ErrorMessage"]
    status, reply = call(night, "PUT", "pulseguide", {"Direction": 9, "Duration": 100})
    assert reply["ErrorNumber"] == INVALID_VALUE


def test_ascom_error_numbers_for_each_refusal(night):
    call(night, "PUT", "connected", {"Connected": "False"})
    assert call(night, "GET", "altitude")[1]["ErrorNumber"] == NOT_CONNECTED
    assert call(night, "GET", "canslewasync")[1]["Value"] is True  # capabilities: no connection
    call(night, "PUT", "connected", {"Connected": "True"})
    assert call(night, "PUT", "synctocoordinates", {"RightAscension": 1, "Declination": 2}
                )[1]["ErrorNumber"] == NOT_IMPLEMENTED
    assert call(night, "PUT", "action", {"Action": "Dance", "Parameters": ""}
                )[1]["ErrorNumber"] == ACTION_NOT_IMPLEMENTED
    call(night, "PUT", "abortslew")
    assert call(night, "PUT", "slewtocoordinates", {"RightAscension": 1, "Declination": 2}
                )[1]["ErrorNumber"] == NOT_IMPLEMENTED  # synchronous slews: not via Alpaca
    assert call(night, "GET", "canslew")[1]["Value"] is False
    call(night, "PUT", "tracking", {"Tracking": "True"})
    assert call(night, "PUT", "slewtoaltazasync", {"Azimuth": 100, "Altitude": 40}
                )[1]["ErrorNumber"] == INVALID_OPERATION
    call(night, "PUT", "park")
    import time

    deadline = time.monotonic() + 90
    while not call(night, "GET", "atpark")[1]["Value"]:
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert call(night, "PUT", "slewtoaltazasync", {"Azimuth": 100, "Altitude": 40}
                )[1]["ErrorNumber"] == INVALID_WHILE_PARKED
    call(night, "PUT", "unpark")


def test_value_not_set_before_a_target_is_given():
    import asyncio

    from virtualstar.alpaca import AlpacaTelescope
    from virtualstar.alpaca.protocol import AlpacaError, Params

    dev = AlpacaTelescope(vss=None)
    dev.connected = True
    with pytest.raises(AlpacaError) as exc:
        asyncio.run(dev.handle("GET", "targetrightascension", Params({})))
    assert exc.value.number == VALUE_NOT_SET


def test_a_request_from_a_foreign_web_page_is_refused_and_loopback_pages_pass(night):
    status, body = call(night, "PUT", "abortslew", headers={"Origin": "https://evil.example"})
    assert status == 403 and "refused" in body
    status, _ = call(night, "GET", "name", headers={"Origin": "http://127.0.0.1:8080"})
    assert status == 200


def test_the_sun_zone_refuses_a_slew_near_the_sun_with_the_servers_reason(day):
    import astropy.units as u
    from astropy.coordinates import get_body
    from astropy.time import Time

    t = day.telescope()
    t.Tracking = True
    utc = call(day, "GET", "utcdate")[1]["Value"]
    # the geocentric direction (GCRS axes are ICRS's; FK5 J2000 is within 0.02")
    sun = get_body("sun", Time(utc.rstrip("Z"), scale="utc"))
    status, reply = call(day, "PUT", "slewtocoordinatesasync",
                         {"RightAscension": (sun.ra + 5 * u.deg).hour, "Declination": sun.dec.deg})
    assert status == 200 and reply["ErrorNumber"] == INVALID_VALUE
    assert "Sun" in reply["ErrorMessage"] and "exclusion" in reply["ErrorMessage"]


def test_discovery_answers_a_unicast_request_with_the_http_port():
    import asyncio

    from virtualstar.alpaca.discovery import start_discovery

    async def main():
        responder = await start_discovery("127.0.0.1", 0, 11123)
        loop = asyncio.get_running_loop()
        with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
            s.setblocking(False)
            s.connect(("127.0.0.1", responder.port))
            s.send(b"hello")  # not a discovery request: ignored
            s.send(b"alpacadiscovery1")
            data = await asyncio.wait_for(loop.sock_recv(s, 1024), 10)
        responder.close()
        return json.loads(data), responder

    doc, responder = asyncio.run(main())
    assert doc == {"AlpacaPort": 11123}
    assert responder.answered == 1 and responder.ignored == 1


BROADCAST_SCRIPT = textwrap.dedent("""
    import asyncio, sys
    from alpaca import discovery
    from virtualstar.alpaca.discovery import start_discovery

    async def main():
        responder = await start_discovery("0.0.0.0", 32227, 11124)
        found = await asyncio.to_thread(discovery.search_ipv4, 1, 1)
        responder.close()
        print(found)

    asyncio.run(main())
""")


def test_alpycas_broadcast_discovery_finds_the_device_inside_a_private_network_namespace():
    if shutil.which("unshare") is None or shutil.which("ip") is None:
        pytest.skip("needs unshare and ip (util-linux, iproute2) for a private network namespace")
    probe = subprocess.run(["unshare", "-n", "true"], capture_output=True)
    if probe.returncode != 0:
        pytest.skip(f"cannot make a private network namespace here: {probe.stderr.decode()[:200]}")
    out = subprocess.run(["unshare", "-n", "sh", "-c",
                          f"ip link set lo up && exec {sys.executable} -c '{BROADCAST_SCRIPT}'"],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    assert "127.0.0.1:11124" in out.stdout


def raw_put(rig, member: str, body: bytes, content_type: str | None,
            encoding: str | None = None) -> tuple[int, str]:
    """A PUT with exactly these body bytes and Content-Type (None: no header), and a
    Content-Encoding if given; (status, text)."""
    import http.client

    conn = http.client.HTTPConnection(rig.address, timeout=60)
    try:
        headers = {"Content-Length": str(len(body))}
        if content_type is not None:
            headers["Content-Type"] = content_type
        if encoding is not None:
            headers["Content-Encoding"] = encoding
        conn.request("PUT", f"/api/v1/telescope/0/{member}", body=body, headers=headers)
        resp = conn.getresponse()
        return resp.status, resp.read().decode("utf-8", errors="replace")
    finally:
        conn.close()


FORM = "application/x-www-form-urlencoded"
MULTIPART = "multipart/form-data; boundary=XyZ"


def _part(headers: str, value: bytes) -> bytes:
    return b"--XyZ\r\n" + headers.encode() + b"\r\n\r\n" + value + b"\r\n"


@pytest.mark.parametrize(("body", "content_type", "says"), [
    (b"TargetDeclination=\xff\xfe12", FORM, "not utf-8 text (byte 18"),
    (b"TargetDeclination=%FF%FE", FORM, "%-escape"),
    (b"TargetDeclination=1", FORM + "; charset=klingon", "charset 'klingon' is unknown"),
    (b"&".join(b"a%d=1" % i for i in range(200)), FORM, "more than 64 fields"),
    (b'{"TargetDeclination": 12}', "application/json", "not application/json"),
    (b"\x00\x01\xfe binary", None, "not utf-8 text"),
    (_part('Content-Disposition: form-data', b"12") + b"--XyZ--\r\n", MULTIPART,
     "multipart body cannot be read"),
    (_part("Content-Type: text/plain", b"12") + b"--XyZ--\r\n", MULTIPART,
     "multipart body cannot be read"),
    (b"no boundary here", "multipart/form-data", "multipart body cannot be read"),
    (b"--other\r\n\r\n", MULTIPART, "multipart body cannot be read"),
    (_part('Content-Disposition: form-data; name="TargetDeclination"\r\n'
           "Content-Type: text/plain; charset=utf-8", b"\xff12") + b"--XyZ--\r\n", MULTIPART,
     "multipart body cannot be read"),
    (_part('Content-Disposition: form-data; name="TargetDeclination"; filename="d.txt"',
           b"12") + b"--XyZ--\r\n", MULTIPART, "is a file upload"),
])
def test_a_malformed_put_body_of_any_kind_is_http_400_saying_why(night, body, content_type,
                                                                 says):
    call(night, "PUT", "connected", {"Connected": "True"})
    status, text = raw_put(night, "targetdeclination", body, content_type)
    assert status == 400, text
    assert says.lower() in text.lower()
    # the façade still answers, and a well-formed multipart PUT is read
    good = _part('Content-Disposition: form-data; name="TargetDeclination"', b"21.5")
    status, text = raw_put(night, "targetdeclination", good + b"--XyZ--\r\n", MULTIPART)
    assert status == 200 and json.loads(text)["ErrorNumber"] == 0
    assert call(night, "GET", "targetdeclination")[1]["Value"] == 21.5


@pytest.mark.parametrize("content_type", [FORM, MULTIPART, None])
@pytest.mark.parametrize("encoding", ["gzip", "deflate", "br"])
def test_a_body_whose_content_encoding_does_not_decode_is_http_400(night, encoding,
                                                                   content_type):
    status, text = raw_put(night, "targetdeclination", b"TargetDeclination=12 not compressed",
                           content_type, encoding)
    assert status == 400, text
    assert "cannot be read" in text or "encoding" in text.lower(), text
    # and a form that is what its Content-Encoding says is read
    import gzip

    good = gzip.compress(b"TargetDeclination=23.25")
    status, text = raw_put(night, "targetdeclination", good, FORM, "gzip")
    assert status == 200 and json.loads(text)["ErrorNumber"] == 0, text
    assert call(night, "GET", "targetdeclination")[1]["Value"] == 23.25


def test_a_put_without_a_content_type_is_read_as_a_form(night):
    status, text = raw_put(night, "connected", b"Connected=True&ClientTransactionID=9", None)
    assert status == 200 and json.loads(text)["ClientTransactionID"] == 9
