"""A plan sent with `run_plan` is a client's input like any other: a plan (or a previous
run's records) with a value of the wrong type or out of range is refused as `bad_request`
naming the field, no program starts, and nothing answers `internal`. (NaN and infinities
are not JSON: the frame itself is refused, tests/hostile/test_hostile_api.py.)

The plans are `vs plan`'s own output for a night of three stars, each with one value
spoiled; one `vs server --emulator` process serves the module and its stderr must hold no
traceback at the end.
"""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import pytest
from hostile_peers import OPERATOR, VEGA_NIGHT, login, vs_server

sys.path.insert(0, str(Path(__file__).parents[1] / "vss"))

from vss_rig import STARS_PROGRAM  # noqa: E402

from virtualstar.astro import UtcTimes, load_site  # noqa: E402
from virtualstar.planning import PlanRequest, load_program, plan_program  # noqa: E402


def _us(iso: str) -> int:
    return int(UtcTimes.from_iso([iso]).to_unix_us()[0])


@pytest.fixture(scope="module")
def plan(tmp_path_factory) -> dict:
    path = tmp_path_factory.mktemp("plan") / "program.toml"
    path.write_text(STARS_PROGRAM)
    doc = plan_program(PlanRequest(load_program(path), _us("2024-05-18T21:22:00Z"),
                                   _us("2024-05-18T21:36:00Z"), load_site())).as_dict()
    doc = json.loads(json.dumps(doc))  # as a client sends it
    assert len(doc["blocks"]) == 3
    return doc


@pytest.fixture(scope="module")
def operator(tmp_path_factory):
    with vs_server(tmp_path_factory.mktemp("vss"), "--speed", "10", "--start",
                   VEGA_NIGHT) as proc:
        op = login(proc.url, OPERATOR)
        yield op
        op.close()
    assert "Traceback" not in proc.stderr, proc.stderr[-3000:]


SPOILED_PLANS = [  # (where, value, a word the refusal must hold)
    (("start_us",), "abc", "start_us"),
    (("start_us",), 10**30, "start_us"),
    (("end_us",), -1, "end_us"),
    (("end_us",), 1.5e15, "end_us"),
    (("setup_s",), -5, "setup_s"),
    (("program",), ["x"], "program"),
    (("blocks",), "all of them", "blocks"),
    (("blocks", 0), "a block", "block"),
    (("blocks", 0, "start_us"), "abc", "start_us"),
    (("blocks", 0, "end_us"), 2**70, "end_us"),
    (("blocks", 1, "start_us"), True, "start_us"),
    (("blocks", 1, "end_el_deg"), 1e300, "end_el_deg"),
    (("blocks", 2, "start_az_deg"), 1e9, "start_az_deg"),
    (("blocks", 2, "priority"), -1e300, "priority"),
    (("blocks", 2, "target"), {"name": "Vega"}, "target"),
    (("blocks", 0, "constraints"), [1, 2], "constraints"),
    (("program_spec",), "not a program", "program_spec"),
    (("program_spec", "targets"), 7, "target"),
    (("program_spec", "targets", 0), 5, "target"),
    (("program_spec", "targets", 0, "min_el_deg"), "low", "min_el_deg"),
    (("program_spec", "targets", 1, "duration_s"), -60, "duration_s"),
    (("program_spec", "targets", 1, "window_us"), [10**30, 10**31], "window_us"),
    (("program_spec", "targets", 2, "kind"), "comet", "kind"),
    (("program_spec", "targets", 2, "closed_loop"), "yes", "closed_loop"),
]


def _spoil(doc: dict, where: tuple, value) -> dict:
    out = copy.deepcopy(doc)
    holder = out
    for key in where[:-1]:
        holder = holder[key]
    holder[where[-1]] = value
    return out


@pytest.mark.parametrize(("where", "value", "word"), SPOILED_PLANS,
                         ids=[f"{'.'.join(map(str, w))}={str(v)[:12]}" for w, v, _ in
                              SPOILED_PLANS])
def test_a_plan_with_a_spoiled_value_is_refused_naming_it_and_starts_nothing(
        operator, plan, where, value, word):
    reply = operator.request("run_plan", {"plan": _spoil(plan, where, value)})
    assert not reply["ok"], reply
    assert reply["error"]["code"] == "bad_request", reply["error"]
    assert word in reply["error"]["message"], reply["error"]["message"]
    status = operator.request("program")
    assert status["ok"] and status["result"].get("state") in (None, "idle", "none"), status


@pytest.mark.parametrize("done", [
    "done", 5, [1], [{"target": "Vega"}],
    [{"target": "Vega", "kind": "star", "repeat": 1, "priority": 1,
      "planned_start_us": "abc", "planned_end_us": 1}],
    [{"target": "Vega", "kind": "star", "repeat": 1, "priority": 1e300,
      "planned_start_us": 1, "planned_end_us": 2}],
    [{"target": "Vega", "kind": "star", "repeat": 1, "priority": 1,
      "planned_start_us": 1, "planned_end_us": 2, "start_us": 2**70}],
], ids=["text", "number", "numbers", "incomplete", "time-text", "huge", "huge-time"])
def test_a_previous_runs_records_that_are_not_records_are_refused(operator, plan, done):
    reply = operator.request("run_plan", {"plan": plan, "done": done})
    assert not reply["ok"] and reply["error"]["code"] == "bad_request", reply
    assert "done" in reply["error"]["message"]
    status = operator.request("program")
    assert status["ok"] and status["result"].get("state") in (None, "idle", "none"), status
