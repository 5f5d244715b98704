"""`vs record`, `vs data` and `vs experiment` as a user runs them, with their errors."""

from __future__ import annotations

import json

import numpy as np
import pytest
from recorder_helpers import free_port
from scipy.io import loadmat
from typer.testing import CliRunner

from virtualstar.cli.main import app

runner = CliRunner()


@pytest.fixture(scope="module")
def recorded(device_url, tmp_path_factory):
    store = tmp_path_factory.mktemp("rec") / "store"
    res = runner.invoke(app, ["record", device_url, "counter", "wave.sine", "--rate", "500",
                              "--duration", "1.2", "--store", f"parquet:{store}", "--json"])
    assert res.exit_code == 0, res.output
    return store, json.loads(res.stdout)


def test_vs_record_writes_every_sample_and_reports_in_json(recorded):
    store, doc = recorded
    assert doc["names"] == ["counter", "wave.sine"] and doc["rate_hz"] == 500
    assert doc["lost"] == 0 and doc["gaps"] == [] and doc["samples"] > 400
    res = runner.invoke(app, ["data", "info", str(store), "--json"])
    assert res.exit_code == 0, res.output
    info = json.loads(res.stdout)
    assert info["samples"] == doc["samples"]
    assert [s["name"] for s in info["signals"]] == ["counter", "wave.sine"]


def test_vs_data_query_gives_a_full_rate_window_and_an_envelope(recorded):
    store, _ = recorded
    res = runner.invoke(app, ["data", "query", f"parquet:{store}", "--from", "+0.1", "--to", "+0.2",
                              "--names", "counter", "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["names"] == ["counter"] and len(doc["t_us"]) == 50  # 0.1 s at 500 Hz
    assert np.all(np.diff(doc["values"]["counter"]) == 2)  # every second tick of 1 kHz
    assert np.all(np.diff(doc["t_us"]) == 2000)
    res = runner.invoke(app, ["data", "query", str(store), "--decimate", "4", "--json"])
    env = json.loads(res.stdout)
    assert 1 <= len(env["t_us"]) <= 4 and sum(env["n"]) > 400
    assert min(env["min"]["wave.sine"]) >= -1 and max(env["max"]["wave.sine"]) <= 1
    res = runner.invoke(app, ["data", "query", str(store), "--from", "+0", "--to", "+0.01", "--csv"])
    lines = res.stdout.strip().splitlines()
    assert lines[0] == "t_us,counter,wave.sine" and len(lines) == 6


def test_vs_data_plot_and_export_write_their_files(recorded, tmp_path):
    store, doc = recorded
    res = runner.invoke(app, ["data", "plot", str(store), "-o", str(tmp_path / "png")])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "png" / "fig6_overview.png").stat().st_size > 10_000
    assert (tmp_path / "png" / "fig7_first_2s.png").stat().st_size > 10_000
    res = runner.invoke(app, ["data", "export", str(store), "--csv", str(tmp_path / "a.csv"),
                              "--mat", str(tmp_path / "a.mat")])
    assert res.exit_code == 0, res.output
    assert len((tmp_path / "a.csv").read_text().splitlines()) == doc["samples"] + 1
    mat = loadmat(tmp_path / "a.mat")
    assert mat["counter"].size == doc["samples"] and mat["wave_sine"].size == doc["samples"]


@pytest.mark.parametrize(("args", "message"), [
    (["--store", "mongo:x"], "unknown store kind 'mongo'"),
    (["--rate", "-5"], "--rate -5.0: expected a positive"),
    (["--duration", "0"], "--duration 0.0: expected a positive"),
    (["--detect-anomalies"], "--detect-anomalies needs axis.<az|el>"),
])
def test_vs_record_rejects_bad_options_clearly(device_url, tmp_path, args, message):
    res = runner.invoke(app, ["record", device_url, "counter", *args])
    assert res.exit_code == 2 and message in res.stderr


def test_vs_record_names_an_unknown_signal_and_an_unreachable_endpoint(device_url, tmp_path):
    res = runner.invoke(app, ["record", device_url, "nope", "--duration", "1",
                              "--store", str(tmp_path / "s")])
    assert res.exit_code == 2 and "no signal nope" in res.stderr
    res = runner.invoke(app, ["record", f"tcp://127.0.0.1:{free_port()}", "counter",
                              "--duration", "1", "--store", str(tmp_path / "s")])
    assert res.exit_code == 2 and "tcp://127.0.0.1" in res.stderr


def test_vs_data_rejects_a_missing_store_and_bad_bounds(recorded, tmp_path):
    store, _ = recorded
    res = runner.invoke(app, ["data", "query", str(tmp_path / "nothing")])
    assert res.exit_code == 2 and "does not exist" in res.stderr
    res = runner.invoke(app, ["data", "query", str(store), "--from", "yesterday"])
    assert res.exit_code == 2 and "--from 'yesterday'" in res.stderr
    res = runner.invoke(app, ["data", "query", str(store), "--from", "+1", "--to", "+0.5"])
    assert res.exit_code == 2 and "empty window" in res.stderr
    res = runner.invoke(app, ["data", "query", str(store), "--names", "counter,bogus"])
    assert res.exit_code == 2 and "unknown signal(s) bogus" in res.stderr


def test_a_window_past_the_end_of_the_store_exits_1_with_the_stores_span(recorded):
    store, _ = recorded
    info = json.loads(runner.invoke(app, ["data", "info", str(store), "--json"]).stdout)
    for args in (["--from", "+3600"], ["--from", "+3600", "--to", "+3700"],
                 ["--to", "1000000"], ["--from", "+3600", "--decimate", "10", "--json"]):
        res = runner.invoke(app, ["data", "query", str(store), *args])
        assert res.exit_code == 1, (args, res.output)
        assert res.stdout == ""  # no empty arrays that look like an answer
        assert "lies after the store's last sample" in res.stderr or \
            "before its first sample" in res.stderr
        assert f"the store spans {info['first_utc']} to {info['last_utc']}" in res.stderr
    for command in (["anomalies"], ["export", "--csv", "/dev/null"]):
        res = runner.invoke(app, ["data", *command, str(store), "--from", "+3600"])
        assert res.exit_code == 1 and "the store spans" in res.stderr


def test_vs_experiment_sine_runs_a_short_night_and_reports_json(tmp_path):
    res = runner.invoke(app, ["experiment", "sine", "--axis", "az", "--hours", "0.005",
                              "--record-hz", "1000", "--out", str(tmp_path / "x"), "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    assert doc["lost"] == 0 and doc["samples_per_signal"] >= 18_000
    assert doc["names"] == ["axis.az.position", "axis.az.current", "axis.az.error_arcsec"]
    assert all((tmp_path / "x" / p).exists() for p in ("fig6_overview.png", "fig7_first_2s.png"))
    res = runner.invoke(app, ["experiment", "sine", "--axis", "ra", "--out", str(tmp_path / "y")])
    assert res.exit_code == 2 and "expected az or el" in res.stderr


def test_vs_record_into_influxdb_and_vs_data_reads_it_back(device_url, influx, tmp_path):
    store = f"influx:{influx.url}/cli"
    res = runner.invoke(app, ["record", device_url, "counter", "--rate", "200", "--duration", "0.8",
                              "--store", store, "--spool", str(tmp_path / "spool"), "--json"])
    assert res.exit_code == 0, res.output
    doc = json.loads(res.stdout)
    res = runner.invoke(app, ["data", "query", store, "--json"])
    assert res.exit_code == 0, res.output
    back = json.loads(res.stdout)
    assert len(back["t_us"]) == doc["samples"] > 100
    assert np.all(np.diff(back["values"]["counter"]) == 5)  # every 5th tick of 1 kHz
    assert back["t_us"][0] == doc["first_t_us"] and back["t_us"][-1] == doc["last_t_us"]
    res = runner.invoke(app, ["data", "info", store, "--json"])
    assert json.loads(res.stdout)["samples"] == doc["samples"]
