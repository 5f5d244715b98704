"""A `vs server --emulator` with passwords, on loopback, under the attacks of issue 25.

Each attack starts the server in a process of its own (lockstep simulated time, paced, so
that the track's figures do not depend on how busy the host is) and attacks it from this
process through raw sockets; two light checks share one server. What is checked is what an observatory would check
afterwards: the operation kept its id and never re-acquired, the tracking error
against the target did not change, the log still holds the operations and names
every wrong password, and the server still answers.
"""

from __future__ import annotations

import contextlib
import os
import threading
import time

import pytest
from hostile_peers import (
    OBSERVER,
    OPERATOR,
    VEGA_NIGHT,
    flood_never_read,
    flood_socket,
    login,
    vs_server,
    ws_frame,
    ws_open,
)

PACE = "10"  # lockstep, at most 10 mount seconds per wall second
PEAK_TOLERANCE_ARCSEC = 0.05  # the goal: the peak error within 0.05″ of the quiet one


def mount_now_us(session) -> int:
    return int(session.request("status")["result"]["mount_time_us"])


def wait_mount_s(session, mount_s: float, *, limit_s: float = 300.0) -> tuple[int, int]:
    """Poll until `mount_s` of mount time passed; return (start, end) mount µs."""
    start = now = mount_now_us(session)
    give_up = time.monotonic() + limit_s
    while now < start + mount_s * 1e6:
        assert time.monotonic() < give_up, "mount time stopped advancing"
        time.sleep(0.2)
        now = mount_now_us(session)
    return start, now


def peak_arcsec(session, from_us: int, to_us: int) -> float:
    """The peak on-target error (the boresight against the target's true place) over the
    window: what an observer would see, not the servo's following error."""
    stats = session.request("errors", {"from_us": from_us, "to_us": to_us})["result"]["stats"]
    assert stats["n"] > 0, stats
    assert stats["on_target_peak_arcsec"] == stats["on_target_peak_arcsec"], stats  # not NaN
    return float(stats["on_target_peak_arcsec"])


def operation_trouble(session, op_id: int) -> list[str]:
    """Log lines that say the operation was interrupted (re-acquired, underrun, ended)."""
    events = session.request("log", {"since": 0, "limit": 10_000})["result"]["events"]
    words = ("resum", "re-acqui", "underrun", "ran dry", "lost", "failed", "aborted")
    return [e["message"] for e in events
            if e["kind"] in ("phase", "operation", "fault", "underrun")
            and any(w in e["message"].lower() for w in words)
            and (e["fields"].get("id") in (None, op_id))]


def test_fifty_thousand_pings_never_read_do_not_disturb_a_lockstep_track(tmp_path):
    with vs_server(tmp_path, "--speed", PACE, "--start", VEGA_NIGHT) as server:
        op = login(server.url, OPERATOR)
        assert op.role == "operator"
        track = op.request("track", {"star": "Vega"})
        assert track["ok"], track
        op_id = track["result"]["id"]
        wait_mount_s(op, 10)  # settled on the target
        quiet = peak_arcsec(op, *wait_mount_s(op, 60))

        # 50 000 pings of ~600 bytes (30 MB): more than every kernel buffer on the way holds
        flood_text = '{"id": "%s", "cmd": "ping"}' % ("x" * 600)
        sock, flood = flood_never_read(server.url, 50_000, give_up_s=3.0, text=flood_text)
        try:
            during = wait_mount_s(op, 60)
            status = op.request("status")  # a legitimate client is answered meanwhile
            noisy = peak_arcsec(op, *during)
            after = op.request("status")["result"]["operation"]
        finally:
            sock.close()
        trouble = operation_trouble(op, op_id)
        op.close()
    assert flood.sent < flood.wanted, "the server read the whole flood: no back-pressure"
    assert status["ok"] and status["result"]["operation"]["id"] == op_id
    assert after["id"] == op_id and after["phase"] == "tracking", after
    assert trouble == []
    assert noisy <= quiet + PEAK_TOLERANCE_ARCSEC, (quiet, noisy)
    assert "Traceback" not in server.stderr


def test_an_authenticated_client_that_never_reads_is_held_to_its_budget(tmp_path):
    """The rule of the unauthenticated flood, at the larger budget of a logged-in observer:
    the server stops reading it, and the operator's track and answers are untouched."""
    with vs_server(tmp_path, "--speed", PACE, "--start", VEGA_NIGHT) as server:
        op = login(server.url, OPERATOR)
        track = op.request("track", {"star": "Vega"})
        assert track["ok"], track
        op_id = track["result"]["id"]
        wait_mount_s(op, 10)
        quiet = peak_arcsec(op, *wait_mount_s(op, 30))
        flooder = login(server.url, OBSERVER)
        assert flooder.role == "observer"
        flood = flood_socket(flooder.sock, 50_000, give_up_s=3.0, text=(
            '{"id": "flood", "cmd": "ping", "params": {"pad": "%s"}}' % ("x" * 600)))
        try:
            during = wait_mount_s(op, 30)
            status = op.request("status")
            noisy = peak_arcsec(op, *during)
        finally:
            flooder.sock.close()
        trouble = operation_trouble(op, op_id)
        op.close()
    assert flood.sent < flood.wanted, "the server read the whole flood: no back-pressure"
    assert status["ok"] and status["result"]["operation"]["id"] == op_id
    assert status["result"]["operation"]["phase"] == "tracking"
    assert trouble == []
    assert noisy <= quiet + PEAK_TOLERANCE_ARCSEC, (quiet, noisy)
    assert "Traceback" not in server.stderr


def guess(url: str, source: str, tries: int) -> list[str]:
    """Open one connection from `source` and send `tries` wrong passwords; return the codes."""
    codes = []
    with contextlib.suppress(ConnectionError, OSError):
        sess = login_raw(url, source)
        for _ in range(tries):
            reply = sess.request("auth", {"client_nonce": os.urandom(16).hex(),
                                          "mac": os.urandom(32).hex()})
            codes.append(reply["error"]["code"])
        sess.close()
    return codes


def login_raw(url: str, source: str):
    from hostile_peers import FrameReader, Session

    sock, rest = ws_open(url, source=source)
    reader = FrameReader(sock, rest)
    reader.json()  # hello
    return Session(sock, reader)


def test_password_guessing_from_many_connections_is_throttled_and_every_checked_guess_logged(
        tmp_path):
    sources = [f"127.0.0.{k}" for k in range(2, 10)]  # eight guessers; the operator on .1
    with vs_server(tmp_path, "--speed", PACE, "--start", VEGA_NIGHT) as server:
        results: dict[str, list[str]] = {s: [] for s in sources}

        def attack(source: str) -> None:
            for _ in range(8):  # 8 connections × 3 guesses from each address
                results[source] += guess(server.url, source, 3)

        threads = [threading.Thread(target=attack, args=(s,)) for s in sources]
        for t in threads:
            t.start()
        for t in threads:
            t.join(300)
        op = login(server.url, OPERATOR)  # the operator, from an address that did not guess
        obs = login(server.url, OBSERVER)
        events = op.request("log", {"since": 0, "limit": 10_000})["result"]["events"]
        op.close()
        obs.close()
    wrong = {s: codes.count("unauthorized") for s, codes in results.items()}
    throttled = sum(codes.count("throttled") for codes in results.values())
    from astcom_client.events import Event
    from virtualstar.eventlog import EventFilter

    # what `vs log --kind auth --level warning` keeps of the server's log
    shown = EventFilter(min_level="warning", kinds=("auth",))
    logged = [e for e in events if shown.matches(Event.from_dict(e))]
    assert op.role == "operator" and obs.role == "observer"
    assert set().union(*map(set, results.values())) <= {"unauthorized", "throttled"}
    assert throttled > 0  # guesses beyond the budget are not even checked
    # every guess that was checked is in the log, with its address
    assert len(logged) == sum(wrong.values())
    for source, n in wrong.items():
        assert sum(e["fields"]["address"] == source for e in logged) == n
        assert 1 <= n <= 20  # at most the lockout's count from one address
    assert all("wrong password" in e["message"] for e in logged)


def test_ten_thousand_connect_close_cycles_leave_the_operations_in_the_log(tmp_path):
    with vs_server(tmp_path, "--speed", PACE, "--start", VEGA_NIGHT) as server:
        op = login(server.url, OPERATOR)
        track = op.request("track", {"star": "Vega"})
        assert track["ok"], track
        op_id = track["result"]["id"]
        before = op.request("log", {"since": 0, "limit": 10_000})["result"]["events"]
        failures = []

        def churn(n: int) -> None:
            for _ in range(n):
                try:
                    sock, _ = ws_open(server.url)
                    sock.sendall(ws_frame(b"\x03\xe8", opcode=8))
                    sock.close()
                except OSError as exc:
                    failures.append(exc)

        threads = [threading.Thread(target=churn, args=(2500,)) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join(600)
        reply = op.request("log", {"since": 0, "limit": 10_000})["result"]
        still = op.request("status")["result"]["operation"]
        op.close()
    kept = {(e["seq"], e["message"]) for e in reply["events"]}
    audit = [e for e in before if e["kind"] not in ("connection", "auth")]
    assert len(failures) < 100, failures[:3]
    assert audit and all((e["seq"], e["message"]) in kept for e in audit)
    assert any(e["kind"] == "phase" and e["fields"].get("id") == op_id for e in reply["events"])
    assert any(e["kind"] == "command" and e["fields"].get("command") == "track"
               for e in reply["events"])
    # the connections that fell out are counted, and they were the only kind to fall out
    assert set(reply["dropped"]) == {"connection"}
    assert reply["dropped"]["connection"] >= 2 * 10_000 - 2 * 2000 - len(failures) * 2
    assert still["id"] == op_id and still["phase"] == "tracking"


@pytest.fixture(scope="module")
def quiet_server(tmp_path_factory):
    """One server for the two tests that neither load it nor need its log to themselves
    (the attacks above each have a server of their own: their figures and logs must be
    theirs alone); no traceback on its stderr at the end."""
    with vs_server(tmp_path_factory.mktemp("quiet"), "--speed", PACE, "--start",
                   VEGA_NIGHT) as server:
        yield server
    assert "Traceback" not in server.stderr, server.stderr[-3000:]


def test_the_embedded_emulators_endpoint_refuses_clients_without_the_password(quiet_server):
    import asyncio

    from astcom_client import Client
    from astcom_client.exceptions import AuthenticationFailed

    async def probe(url: str) -> tuple[str, dict]:
        refused = ""
        try:
            async with await Client.connect(url, name="stranger"):
                pass
        except AuthenticationFailed as exc:
            refused = str(exc)
        try:
            async with await Client.connect(url, password="guess", name="stranger"):
                pass
        except AuthenticationFailed as exc:
            refused += " | " + str(exc)
        async with await Client.connect(url, password=OBSERVER, name="observer") as c:
            values = await c.read(["mount.state_name"])
        return refused, values

    server = quiet_server
    op = login(server.url, OPERATOR)
    track = op.request("track", {"star": "Vega"})
    refused, values = asyncio.run(probe(server.emulator_url))
    still = op.request("status")["result"]["operation"]
    op.close()
    assert "takes the server's operator password and its observer password" in server.line
    assert refused.count("password") >= 2, refused
    assert "mount.state_name" in values
    assert still["id"] == track["result"]["id"] and still["phase"] == "tracking"


def test_load_model_of_a_file_that_is_no_model_is_refused_without_stalling_the_server(
        quiet_server, tmp_path):
    fifo = tmp_path / "model.fifo"
    os.mkfifo(fifo)  # no writer: reading it would wait for ever
    huge = tmp_path / "huge.json"
    with open(huge, "wb") as f:
        f.truncate(64 << 20)  # a sparse 64 MiB file
    cases = {str(fifo): "FIFO", "/dev/zero": "character device", str(tmp_path): "directory",
             str(huge): "more than", "model\x00.json": "NUL character"}
    server = quiet_server
    op = login(server.url, OPERATOR)
    replies = {path: op.request("load_model", {"path": path}) for path in cases}
    status = op.request("status")
    op.close()
    for path, words in cases.items():
        reply = replies[path]
        assert reply["ok"] is False and reply["error"]["code"] == "bad_request", reply
        message = reply["error"]["message"]
        assert words in message and (path in message or repr(path) in message), message
    assert status["ok"] and status["result"]["pointing_model"] is None
    assert "Traceback" not in server.stderr
