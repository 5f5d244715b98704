"""The `astcom` command line lists, gets, sets, calls and streams a live endpoint."""

import csv
import json

import numpy as np
import pytest
from astcom_helpers import PASSWORDS, device_in_thread
from typer.testing import CliRunner

from astcom_client.cli import app

runner = CliRunner()
OPERATOR = {"ASTCOM_PASSWORD": PASSWORDS["operator"]}


@pytest.fixture(scope="module")
def live() -> dict:
    with device_in_thread("ws://127.0.0.1:0") as state:
        yield state


def astcom(*args: str, env: dict | None = None):
    return runner.invoke(app, list(args), env=env if env is not None else OPERATOR)


def test_list_json_gives_every_entry_with_its_fields(live: dict) -> None:
    result = astcom("list", live["url"], "--json")
    assert result.exit_code == 0, result.output
    entries = json.loads(result.stdout)
    assert {e["name"] for e in entries} == {e.name for e in live["device"].collection}
    for entry in entries:
        assert {"name", "type", "kind", "access", "unit", "doc"} <= set(entry)
    amplitude = next(e for e in entries if e["name"] == "wave.amplitude")
    assert (amplitude["type"], amplitude["kind"], amplitude["access"]) == ("f64", "parameter", "rw")


def test_list_prints_a_table_by_default(live: dict) -> None:
    result = astcom("list", live["url"], "--prefix", "wave.")
    assert result.exit_code == 0 and "wave.frequency_hz" in result.stdout
    assert "counter" not in result.stdout


def test_set_then_get_shows_the_new_values(live: dict) -> None:
    assert astcom("set", live["url"], "gains", "[3, 2, 1]").exit_code == 0
    assert astcom("set", live["url"], "label", "mount one").exit_code == 0
    result = astcom("get", live["url"], "gains", "label", "counter", "--json")
    assert result.exit_code == 0, result.output
    got = json.loads(result.stdout)
    assert got["values"]["gains"] == [3.0, 2.0, 1.0] and got["values"]["label"] == "mount one"
    assert got["values"]["counter"] <= got["tick"]
    assert "mount one" in astcom("get", live["url"], "label").stdout


def test_set_explains_a_value_that_does_not_fit(live: dict) -> None:
    result = astcom("set", live["url"], "gains", "[1, 2]")
    assert result.exit_code == 2 and "shape" in result.stderr
    result = astcom("set", live["url"], "wave.amplitude", "big")
    assert result.exit_code == 2 and "example: 1.5" in result.stderr
    result = astcom("set", live["url"], "counter", "3")
    assert result.exit_code == 1 and "read-only" in result.stderr


def test_call_parses_arguments_from_the_listed_signature(live: dict) -> None:
    result = astcom("call", live["url"], "math.add", "1.25", "2", "--json")
    assert result.exit_code == 0, result.output
    assert json.loads(result.stdout) == {"name": "math.add", "value": 3.25}
    assert astcom("call", live["url"], "math.sum", "[1, 2, 3.5]").stdout.strip() == "6.5"
    result = astcom("call", live["url"], "math.add", "1")
    assert result.exit_code == 2 and "takes 2 arguments" in result.stderr
    result = astcom("call", live["url"], "device.fail")
    assert result.exit_code == 1 and "always fails" in result.stderr


def test_stream_json_counts_samples_and_writes_the_csv(live: dict, tmp_path) -> None:
    path = tmp_path / "wave.csv"
    result = astcom("stream", live["url"], "counter", "wave.sine", "--rate", "200",
                    "--duration", "0.6", "--out", str(path), "--json")
    assert result.exit_code == 0, result.output
    summary = json.loads(result.stdout)
    assert summary["rate_hz"] == 200.0 and summary["lost"] == 0
    assert summary["duration_s"] > 0
    assert summary["samples"]["counter"] == summary["samples"]["wave.sine"] > 0
    with path.open() as handle:
        rows = list(csv.reader(handle))
    assert rows[0] == ["t_us", "tick", "counter", "wave.sine"]
    data = np.array(rows[1:], dtype=float)
    assert len(data) == summary["samples"]["counter"]
    assert np.all(np.diff(data[:, 1]) == 5)  # 1000 Hz loop / 200 Hz
    np.testing.assert_array_equal(data[:, 1], data[:, 2])  # counter == tick
    np.testing.assert_array_equal(np.diff(data[:, 0]), 5000)  # µs between samples


def test_a_wrong_password_exits_with_the_reason(live: dict) -> None:
    result = astcom("get", live["url"], "counter", env={"ASTCOM_PASSWORD": "nope"})
    assert result.exit_code == 1 and "authentication failed" in result.stderr
    result = astcom("get", live["url"], "counter", "--password", PASSWORDS["observer"])
    assert result.exit_code == 0
    result = astcom("set", live["url"], "wave.offset", "1", "--password", PASSWORDS["observer"])
    assert result.exit_code == 1 and "operator" in result.stderr


def test_bad_urls_and_unreachable_endpoints_exit_with_code_2() -> None:
    result = astcom("list", "http://127.0.0.1:1")
    assert result.exit_code == 2 and "ws://HOST:PORT" in result.stderr
    result = astcom("list", "tcp://127.0.0.1:1", "--timeout", "2")
    assert result.exit_code == 2 and "cannot connect" in result.stderr


def test_unknown_names_are_reported_with_suggestions(live: dict) -> None:
    result = astcom("get", live["url"], "wave.sin")
    assert result.exit_code == 1 and "did you mean" in result.stderr
