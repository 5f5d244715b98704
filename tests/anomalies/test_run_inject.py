"""`vs run --inject`: an emulator parameter written at a time of the night (fault rehearsal);
a wrong one is refused before the night runs."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner
from vss_nights import make_plan

from virtualstar.cli.main import app
from virtualstar.recorder.parquet_store import ParquetStoreReader


@pytest.fixture(scope="module")
def plan_file(tmp_path_factory):
    work = tmp_path_factory.mktemp("inject")
    make_plan(work)
    return work / "plan.json"


@pytest.mark.parametrize(("args", "message"), [
    (["--inject", "axis.az.inject_winding_fault=0.2"], "NAME=VALUE@WHEN"),
    (["--inject", "axis.az.inject_winding_fault=lots@+60"], "NAME=VALUE@WHEN"),
    (["--inject", "=0.2@+60"], "no parameter name"),
    (["--inject", "axis.az.inject_winding_fault=0.2@yesterday"], "NAME=VALUE@WHEN"),
])
def test_a_malformed_injection_is_refused_with_exit_2(plan_file, args, message):
    result = CliRunner().invoke(app, ["run", str(plan_file), "--emulator", *args])
    assert result.exit_code == 2
    assert message in result.stderr


def test_an_injection_needs_the_emulator(plan_file):
    result = CliRunner().invoke(app, ["run", str(plan_file), "--server", "ws://127.0.0.1:9",
                                      "--inject", "axis.az.inject_winding_fault=0.2@+60"])
    assert result.exit_code == 2
    assert "--emulator" in result.stderr


def test_an_unknown_parameter_is_refused_before_the_night_runs(plan_file):
    result = CliRunner().invoke(app, ["run", str(plan_file), "--emulator", "--json",
                                      "--inject", "axis.az.no_such_thing=1@+60"])
    assert result.exit_code == 2
    assert "axis.az.no_such_thing" in json.loads(result.stdout)["error"]["message"]


def test_an_injection_is_written_at_its_time_and_kept_in_the_recording(plan_file, tmp_path):
    doc = json.loads(plan_file.read_text())
    doc["blocks"] = doc["blocks"][:1]  # the first star alone: three minutes of mount time
    doc["end_us"] = doc["blocks"][0]["end_us"]
    short = tmp_path / "plan.json"
    short.write_text(json.dumps(doc))
    store = tmp_path / "night"
    result = CliRunner().invoke(app, [
        "run", str(short), "--emulator", "--json", "--record", "axis.az.current",
        "--record-rate", "100", "--store", f"parquet:{store}",
        "--inject", "axis.az.inject_winding_fault=0.2@+120"])
    assert result.exit_code == 0, result.output
    # the emulator's own log says when the parameter changed, from what to what
    writes = [e for e in ParquetStoreReader(store).events()
              if e.kind == "param" and e.fields.get("name") == "axis.az.inject_winding_fault"]
    assert len(writes) == 1, writes
    assert 0 <= writes[0].t_us - (doc["start_us"] + 120_000_000) < 1000
    assert (writes[0].fields["old"], writes[0].fields["new"]) == (0.0, 0.2)
