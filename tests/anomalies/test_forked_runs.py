"""A variant forked off a run at a mount time (`run_plan_on_emulator(branches=)`,
`run_sine_experiment(branches=)`) is the same recording, bit for bit, as the variant
simulated whole from the start: the anomaly tests' faulty nights and sine recordings are
forked off their clean ones (test_vss_nights.py, conftest.py)."""

from __future__ import annotations

import numpy as np
import pytest
from anomaly_helpers import CASES, record
from vss_nights import RATE_HZ, SIGNALS, injections, utc_us

from virtualstar.astro import load_site
from virtualstar.planning import PlanRequest, load_program, plan_program
from virtualstar.planning.emulated import Branch, Branches, TimedWrite, run_plan_on_emulator
from virtualstar.planning.exceptions import PlanningError
from virtualstar.planning.recording import RunRecording
from virtualstar.recorder.experiment import Injection, SineBranch
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
FORK_S, STANDBY_S, FAULT_S, STOP_S = 30, 35, 40, 100  # after the plan's start: fork, a
# variant on standby, every fault, stop


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
    # variants wait at FORK_S and, on standby, at STANDBY_S and after the fault: the
    # variant runs in the one forked last before its fault
    forked = run_plan_on_emulator(
        plan, record=_recording(work / "main"), until_us=stop_us,
        branches=Branches(start + FORK_S * 1_000_000, 1, lambda result: [
            Branch(writes, stop_us, (f"parquet:{work / 'branch'}",))],
            standby_us=[start + s * 1_000_000 for s in (FAULT_S + 5, STANDBY_S)]))
    assert [b["recording"]["samples_per_signal"] for b in forked["branches"]] == \
        [whole["recording"]["samples_per_signal"]]
    assert [b["forked_at_us"] for b in forked["branches"]] == [start + STANDBY_S * 1_000_000]
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


def test_each_order_runs_in_the_variant_forked_last_before_its_start():
    # forked at 10 (two), 20, 30 and 40 s; orders starting at 35, 12, 30 and 50 s (the
    # last by its stop): the latest starts choose first, and the two children at 10 s
    # leave every order one
    from virtualstar.planning.emulated import _assign

    s = 1_000_000
    orders = [Branch([TimedWrite(35 * s, "x", 1.0)]), Branch([TimedWrite(12 * s, "x", 1.0)]),
              Branch([TimedWrite(30 * s, "x", 1.0), TimedWrite(60 * s, "x", 0.0)]),
              Branch((), 50 * s)]
    forked_at = [10 * s, 10 * s, 20 * s, 30 * s, 40 * s]
    assert _assign(orders, forked_at, 10 * s) == [3, 0, 2, 4]
    # two orders at the same start, a single child at their point: the second one goes back
    # to the latest point left
    same = [Branch([TimedWrite(45 * s, "x", 1.0)]), Branch([TimedWrite(45 * s, "x", 1.0)])]
    assert sorted(_assign(same, forked_at, 10 * s)) == [3, 4]


def test_branch_orders_that_write_before_the_fork_are_refused(short_plan):
    plan, start, work = short_plan
    at_us = start + FORK_S * 1_000_000
    with pytest.raises(PlanningError, match="cannot write or stop before it"):
        run_plan_on_emulator(plan, until_us=at_us + 1_000_000, branches=Branches(
            at_us, 2, lambda result: [Branch(injections(at_us - 100)), Branch()]))


def _same_samples(a: ParquetStoreReader, b: ParquetStoreReader, to_us: int) -> int:
    wa, wb = a.window(a.time_range()[0], to_us), b.window(b.time_range()[0], to_us)
    assert np.array_equal(wa.t_us, wb.t_us)
    for name in wa.columns:
        assert np.array_equal(wa.columns[name], wb.columns[name]), name
    return len(wa.t_us)


def test_a_sine_recording_forked_at_its_faults_records_what_the_whole_one_records(tmp_path):
    # three minutes of the sine, the three growths (CASES) injected at 60 s, the forked
    # variant stopped at 120 s; the whole one (the same sine, the same faults) runs on
    faults = tuple(Injection(60.0, j.name, j.value) for j in
                   CASES["clock drift, heat runaway and a loosened part rattling louder"][0])
    whole = record(tmp_path / "whole", faults, minutes=3.0, detect=True)
    run = record(tmp_path / "run", (), minutes=3.0, detect=True,
                 branches=(SineBranch(60.0, faults, str(tmp_path / "branch"), 120.0),))
    (branch,) = run.branches
    assert branch["trajectory_t0_us"] == whole.trajectory_t0_us == run.trajectory_t0_us
    a, b = ParquetStoreReader(whole.store), ParquetStoreReader(branch["store"])
    end_us = b.time_range()[1] + 1
    assert end_us - b.time_range()[0] > 119_000_000
    assert _same_samples(a, b, end_us) > 119_000
    assert [(e.t_us, e.kind, e.fields) for e in a.events() if e.kind == "param"] == \
        [(e.t_us, e.kind, e.fields) for e in b.events() if e.kind == "param"] != []
    # the run it was forked off went on without the faults: the same until 60 s only
    clean = ParquetStoreReader(run.store)
    fault_us = run.trajectory_t0_us + 60_000_000
    assert _same_samples(clean, b, fault_us) > 59_000
    assert not np.array_equal(clean.window(fault_us, end_us).columns["axis.az.temperature"],
                              b.window(fault_us, end_us).columns["axis.az.temperature"])
