"""Every value a client can send is checked before the supervisor sees it; no input
produces `internal` or a traceback; a refused command never ends the running track.

One `vs server --emulator` process (lockstep, paced) serves the module; its stderr is
kept in a file and must hold no traceback at the end.
"""

from __future__ import annotations

import dataclasses
import json
import math
import typing

import pytest
from hostile_peers import OPERATOR, VEGA_NIGHT, login, stranger, vs_server, ws_frame
from hypothesis import HealthCheck, example, given, settings
from hypothesis import strategies as st

from virtualstar.server.commands import COMMANDS

NAN, INF = math.nan, math.inf
NOT_JSON = [NAN, INF, -INF]  # JSON has no such numbers: on the wire its parser refuses them
HUGE = [1e300, -1e300, 2**70, -(2**70), 10**30]
# Parameters whose domain has no negative values: durations, counts, times, rates, sequence
# numbers and the angles that run from 0 (right ascension, azimuth)
NEVER_NEGATIVE = {"settle_s", "duration_s", "max_wait_s", "max_points", "since", "limit", "id",
                  "from_us", "to_us", "rate_arcsec_s", "ra_deg", "az_deg"}
# What a command needs besides the parameter under test, so that only that one is wrong
# (and its own range check is what refuses it)
NEEDS = {"slew": {"star": "Vega"}, "track": {"star": "Vega"},
         "pointing_sample": {"star": "Vega"}, "move": {"az_rate_deg_s": 0.5},
         "offset": {"axis": "dec"}, "guide": {"north_arcsec": 1.0}}
NEEDS_FOR = {("offset", "seconds"): {"axis": "path"},  # seconds of time: along a pass only
             ("guide", "north_arcsec"): {"east_arcsec": 1.0}}


def numeric_parameters() -> list[tuple[str, str]]:
    out = []
    for cmd, command in sorted(COMMANDS.items()):
        hints = typing.get_type_hints(command.params)
        for f in dataclasses.fields(command.params):
            kinds = typing.get_args(hints[f.name]) or (hints[f.name],)
            if int in kinds or float in kinds:
                out.append((cmd, f.name))
    return out


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    with vs_server(tmp_path_factory.mktemp("vss"), "--speed", "10", "--start",
                   VEGA_NIGHT) as proc:
        yield proc
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]


@pytest.fixture(scope="module")
def tracking(server):
    """An operator session with Vega being tracked."""
    op = login(server.url, OPERATOR)
    reply = op.request("track", {"star": "Vega"})
    assert reply["ok"], reply
    yield op, reply["result"]["id"]
    op.close()


def test_the_numeric_parameters_are_those_the_api_documents():
    found = numeric_parameters()
    assert len(found) >= 20  # a guard against the table losing its types
    assert ("pointing_sample", "settle_s") in found and ("log", "since") in found


def bad_values(name: str) -> list:
    """Values of a numeric parameter that JSON can carry and its range check must refuse."""
    values: list = [*HUGE]
    if name in NEVER_NEGATIVE:
        values += [-5, -1e-3] if name not in ("duration_s", "rate_arcsec_s") else [-5, 0]
    return values


def own_check(cmd: str, name: str, value) -> str:
    """What the parameter's own check says of a finite bad value: an integer parameter
    given a fraction, that it expects an int; else its range's upper bound (commands.py's
    table: the field's `within`, or the defaults for an int or a float)."""
    from virtualstar.server.commands import ANY_FLOAT, INT64

    command = COMMANDS[cmd].params
    f = next(f for f in dataclasses.fields(command) if f.name == name)
    kinds = typing.get_args(typing.get_type_hints(command)[name])
    kinds = kinds or (typing.get_type_hints(command)[name],)
    if float not in kinds and isinstance(value, float):
        return "expected int"
    within = f.metadata.get("within", INT64 if float not in kinds else ANY_FLOAT)
    return f"{within.hi:g}"


def params_with(cmd: str, name: str, value) -> dict:
    """The command's parameters with `value` for `name` and, besides, what it needs."""
    if cmd in ("slew", "track", "pointing_sample") and name in ("ra_deg", "dec_deg"):
        return {"ra_deg": 10.0, "dec_deg": 10.0, name: value}
    if cmd in ("slew", "track", "pointing_sample") and name in ("az_deg", "el_deg"):
        return {"az_deg": 10.0, "el_deg": 40.0, name: value}
    return {**NEEDS_FOR.get((cmd, name), NEEDS.get(cmd, {})), name: value}


@pytest.mark.parametrize(("cmd", "name"), numeric_parameters())
def test_nan_infinite_huge_and_impossible_negative_values_are_refused_and_end_nothing(
        tracking, cmd, name):
    op, op_id = tracking
    for value in [*NOT_JSON, *bad_values(name)]:
        # NaN and the infinities leave as the tokens Python writes; JSON has none
        frame = json.dumps({"id": 1, "cmd": cmd, "params": params_with(cmd, name, value)})
        reply = op.request(cmd, raw=frame)
        assert reply["ok"] is False, (cmd, name, value, reply)
        assert reply["error"]["code"] == "bad_request", (cmd, name, value, reply)
        # each refused by its own check: the parser for what JSON cannot hold, else the
        # parameter's own check, which names it and says what it expects
        message = reply["error"]["message"]
        if math.isfinite(value):
            assert name in message and own_check(cmd, name, value) in message, (cmd, name,
                                                                                 value, reply)
        else:
            assert "not a JSON number" in message, (cmd, name, value, reply)
        running = op.request("status")["result"]["operation"]
        assert running["id"] == op_id and running["phase"] == "tracking", (cmd, name, value)


def test_nan_and_infinities_handed_in_process_are_refused_by_each_parameters_own_check():
    """The façades hand values on in-process (Alpaca's JSON Parameters are read by Python's
    json, which takes NaN and Infinity): there no parser stands in front of the ranges."""
    from vss_rig import run_lockstep_scenario

    from virtualstar.server.exceptions import VssError

    async def scenario(vss, clock):
        track = await vss.server.call("track", {"star": "Vega"})
        while (await vss.server.call("status"))["operation"]["phase"] != "tracking":
            await clock.sleep(1.0)
        refused, let_through = [], []
        for cmd, name in numeric_parameters():
            for value in NOT_JSON:
                try:
                    await vss.server.call(cmd, params_with(cmd, name, value))
                    let_through.append((cmd, name, value))
                except VssError as exc:
                    refused.append((cmd, name, value, exc.code, str(exc)))
        return track["id"], refused, let_through, await vss.server.call("status")

    op_id, refused, let_through, status = run_lockstep_scenario(VEGA_NIGHT, scenario)
    assert not let_through
    for cmd, name, value, code, message in refused:
        assert code == "bad_request" and name in message, (cmd, name, value, code, message)
    assert status["operation"]["id"] == op_id and status["operation"]["phase"] == "tracking"


@pytest.mark.parametrize(("frame", "words"), [
    ('{"id": 1, "cmd": "pointing_sample", "params": {"star": "Vega", "settle_s": 1e12}}',
     "settle_s"),
    ('{"id": 2, "cmd": "track", "params": {"star": "Vega", "duration_s": 1e300}}', "duration_s"),
    ('{"id": 3, "cmd": "errors", "params": {"max_points": -5}}', "max_points"),
    ('{"id": 4, "cmd": "log", "params": {"since": ' + str(2**70) + "}}", "since"),
    ("[" * 100_000 + "]" * 100_000, "nests deeper"),
    ('{"id": ' + "9" * 5000 + ', "cmd": "ping"}', "5000 characters"),
    ('{"id": 5, "cmd": "ping", "params": {"x": 1e999}}', "beyond the range"),
    ('{"id": 6, "cmd": "status", "params": {"a": ' + '{"b":' * 1000 + "1" + "}" * 1000 + "}}",
     "nests deeper"),
])
def test_the_values_of_the_issue_are_refused_as_bad_requests_and_the_track_goes_on(
        tracking, frame, words):
    op, op_id = tracking
    reply = op.request("raw", raw=frame)
    assert reply["ok"] is False and reply["error"]["code"] == "bad_request", reply
    assert words in reply["error"]["message"]
    running = op.request("status")["result"]["operation"]
    assert running["id"] == op_id and running["phase"] == "tracking"


# -- fuzz ---------------------------------------------------------------------------------
NAMES = sorted({f.name for c in COMMANDS.values() for f in dataclasses.fields(c.params)})
leaves = (st.none() | st.booleans() | st.integers() | st.integers(min_value=2**60)
          | st.floats() | st.text(max_size=40) | st.sampled_from(["Vega", "10 40", "-1 95"]))
values = st.recursive(leaves, lambda inner: st.lists(inner, max_size=3)
                      | st.dictionaries(st.text(max_size=8), inner, max_size=3), max_leaves=8)
params = st.dictionaries(st.sampled_from(NAMES) | st.text(max_size=8), values, max_size=4)
ids = st.integers() | st.text(max_size=20) | st.none() | st.floats() | st.booleans()
commands = st.sampled_from(sorted([*COMMANDS, "auth"])) | st.text(max_size=12)
documents = st.builds(lambda i, c, p: json.dumps({"id": i, "cmd": c, "params": p}),
                      ids, commands, params)
frames = documents | st.text(max_size=300) | values.map(json.dumps)


class Operators:
    """Two operator sessions for the fuzz: `fuzzed` receives the frames, `stopper` ends what
    a frame started. Each password check costs a fifth of a second (the server passes at
    most 5 a second over all addresses: docs/vss-api.md, "Limits"), so `fuzzed` is renewed
    only when a frame could have changed it: an `auth` command (a wrong MAC counts towards
    the three that close the connection), or a session no longer answered as an operator."""

    def __init__(self, url: str) -> None:
        self.url = url
        self.fuzzed = login(url, OPERATOR)
        self.stopper = login(url, OPERATOR)

    def renew(self) -> None:
        self.fuzzed.close()
        self.fuzzed = login(self.url, OPERATOR)

    def close(self) -> None:
        self.fuzzed.close()
        self.stopper.close()


@pytest.fixture(scope="module")
def operators(server):
    ops = Operators(server.url)
    yield ops
    ops.close()


def is_auth(frame: str) -> bool:
    try:
        doc = json.loads(frame)
    except ValueError:
        return False
    return isinstance(doc, dict) and doc.get("cmd") == "auth"


@settings(max_examples=150, deadline=None,
          suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])
@given(frame=frames)
# commands that wait, so that every run ends one with `stop` (and reads its answer)
@example(frame='{"id": 1, "cmd": "slew", "params": {"star": "Vega"}}')
@example(frame='{"id": 2, "cmd": "track", "params": {"star": "Vega", "wait": true, '
               '"duration_s": 3600}}')
@example(frame='{"id": 3, "cmd": "pointing_sample", "params": {"star": "Vega", '
               '"settle_s": 600}}')
def test_no_frame_gets_internal_and_the_server_keeps_answering(server, operators, frame):
    """Each frame goes out on an operator session, and its answer is read and checked. A
    command that waits (a slew landing, a settle, `wait`, `track` or `run_plan` with wait)
    and has not answered within a second is ended by the other operator's `stop`, repeated
    until it answers: its answer (the aborted operation) is checked like any other. A `stop`
    that comes before the command started its operation ends nothing; the next one does.
    Then a new peer connects and is answered, and both operators still are."""
    op = operators.fuzzed
    op.sock.sendall(ws_frame(frame))
    reply = op.next_reply(1.0)
    for _ in range(30):
        if reply is not None:
            break
        operators.stopper.request("stop")
        reply = op.next_reply(1.0)
    assert reply is not None, (frame, "no answer, even after 30 stops")
    if reply.get("ok") is False:
        assert reply["error"]["code"] != "internal", (frame, reply)
    again = stranger(server.url)
    assert again.request("ping")["result"] == {"pong": True}
    again.close()
    assert operators.stopper.request("ping")["result"] == {"pong": True}
    # whatever the frame started ends here; and the fuzzed session is still an operator's
    stopped = op.request("stop")
    if is_auth(frame) or not stopped["ok"]:
        operators.renew()
        stopped = operators.fuzzed.request("stop")
    assert stopped["ok"], (frame, stopped)
