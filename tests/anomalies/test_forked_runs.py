"""A variant forked off a lockstep run at a mount time (`run_plan_on_emulator(branches=)`)
is the same recording, bit for bit, as the variant simulated whole from the start: the
anomaly tests' faulty nights are forked off their clean night (test_vss_nights.py)."""

from __future__ import annotations

import numpy as np
import pytest
from vss_nights import RATE_HZ, SIGNALS, injections, utc_us

from virtualstar.astro import load_site
from virtualstar.planning import PlanRequest, load_program, plan_program
from virtualstar.planning.emulated import Branch, Branches, run_plan_on_emulator
from virtualstar.planning.exceptions import PlanningError
from virtualstar.planning.recording import RunRecording
from virtualstar.recorder.parquet_store import ParquetStoreReader

PROGRAM = """
[program]
name = "a short night to fork"
[defaults]
duration_s = 60
min_el_deg = 20
sun_max_el_deg = -6
[[target]]
star = "Vega"
priority = 3
[[target]]
star = "Deneb"
priority = 2
"""
START = "2021-07-21T01:20:00Z"
FORK_S, FAULT_S, STOP_S = 30, 40, 100  # after the plan's start: fork, every fault, stop


@pytest.fixture(scope="module")
def short_plan(tmp_path_factory):
    work = tmp_path_factory.mktemp("forked")
    (work / "program.toml").write_text(PROGRAM)
    start = utc_us(START)
    return plan_program(PlanRequest(load_program(work / "program.toml"), start,
                                    start + 180_000_000, load_site())).as_dict(), start, work


def _recording(store) -> RunRecording:
    return RunRecording(SIGNALS, RATE_HZ, (f"parquet:{store}",))


def test_a_variant_forked_at_a_mount_time_records_what_the_whole_variant_records(short_plan):
    plan, start, work = short_plan
    fault_us, stop_us = start + FAULT_S * 1_000_000, start + STOP_S * 1_000_000
    writes = injections(fault_us)  # all six degradations of the VSS nights
    whole = run_plan_on_emulator(plan, record=_recording(work / "whole"), writes=writes,
                                 until_us=stop_us)
    forked = run_plan_on_emulator(
        plan, record=_recording(work / "main"), until_us=stop_us,
        branches=Branches(start + FORK_S * 1_000_000, 1, lambda result: [
            Branch(writes, stop_us, (f"parquet:{work / 'branch'}",))]))
    assert [b["recording"]["samples_per_signal"] for b in forked["branches"]] == \
        [whole["recording"]["samples_per_signal"]]
    a, b, main = (ParquetStoreReader(work / n) for n in ("whole", "branch", "main"))
    assert a.time_range() == b.time_range()
    assert main.time_range()[0] == a.time_range()[0]
    ta, tb = a.window(*a.time_range()), b.window(*b.time_range())
    assert np.array_equal(ta.t_us, tb.t_us) and len(ta.t_us) > 200_000
    for name in SIGNALS:
        assert np.array_equal(ta.columns[name], tb.columns[name]), name

    def log(reader):
        # the night's events until the stop: less the recording session's own (ids, wall
        # times) and the clients' connections (the fault writer connects at the fork, not
        # at the start); the recorder reads the logs every wall second, so the last
        # events, after the stop, may come too late for its end
        return [(e.t_us, e.source, e.level, e.kind, e.message, e.fields)
                for e in reader.events() if e.source != "recorder"
                and e.kind != "connection" and e.t_us < stop_us]

    assert log(a) == log(b) and any(e[3] == "param" for e in log(b))
    # not vacuous: the variant differs from the run it was forked off after its faults
    # only, and the run it was forked off went on without them
    tm = main.window(*main.time_range())
    before, after = tb.t_us < fault_us, tb.t_us > fault_us + 5_000_000
    current = "axis.az.current"
    assert np.array_equal(tm.columns[current][before], tb.columns[current][before])
    assert not np.array_equal(tm.columns[current][after], tb.columns[current][after])
    assert not any(e[3] == "param" for e in log(main))


def test_branch_orders_that_write_before_the_fork_are_refused(short_plan):
    plan, start, work = short_plan
    at_us = start + FORK_S * 1_000_000
    with pytest.raises(PlanningError, match="cannot write or stop before it"):
        run_plan_on_emulator(plan, until_us=at_us + 1_000_000, branches=Branches(
            at_us, 2, lambda result: [Branch(injections(at_us - 100)), Branch()]))
