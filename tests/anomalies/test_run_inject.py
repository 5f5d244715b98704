"""`vs run --inject`: an emulator parameter written at a time of the night (fault rehearsal);
a wrong one is refused before the night runs."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner
from vss_nights import make_plan

from virtualstar.cli.main import app


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
