"""`vs plan` on the command line: the JSON contract, the picture, and clear errors for a
wrong program file or window (exit 2, naming the file, the target and the key)."""

from __future__ import annotations

import json

import pytest
from typer.testing import CliRunner

from virtualstar.cli.main import app

runner = CliRunner()
EXAMPLE = "catalogs/data/program-example.toml"
BLOCK_FIELDS = {"target", "kind", "repeat", "priority", "start_utc", "end_utc", "start_az_deg",
                "start_el_deg", "end_az_deg", "end_el_deg", "slew_s", "constraints",
                "duration_s", "start_us", "end_us"}


def test_plan_json_lists_blocks_and_left_out_targets_and_writes_the_plan_and_png(tmp_path):
    out, png = tmp_path / "night.json", tmp_path / "night.png"
    result = runner.invoke(app, ["plan", EXAMPLE, "--night", "2024-05-18", "--json",
                                 "-o", str(out), "--png", str(png)])
    assert result.exit_code == 0, result.output
    doc = json.loads(result.stdout)
    assert json.loads(out.read_text()) == doc
    assert doc["blocks"] and all(set(b) >= BLOCK_FIELDS for b in doc["blocks"])
    assert {x["target"] for x in doc["left_out"]} >= {"Altair", "Jupiter"}
    assert all(x["reason"] for x in doc["left_out"])
    assert doc["priority_weighted_hours"] == pytest.approx(
        sum(b["priority"] * b["duration_s"] / 3600 for b in doc["blocks"]))
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plan_table_names_every_block_and_the_reasons():
    result = runner.invoke(app, ["plan", EXAMPLE, "--from", "2024-05-18T20:30:00Z",
                                 "--to", "2024-05-18T23:00:00Z"])
    assert result.exit_code == 0, result.output
    assert "Vega" in result.stdout and "left out: Jupiter:" in result.stdout


@pytest.mark.parametrize(("text", "expected"), [
    ("[[target]]\nstar = 'Vega'\nradec = '1h +2d'\n", "give exactly one of"),
    ("[[target]]\nstar = 'Vega'\npriority = -1\n", "priority = -1"),
    ("[[target]]\nstar = 'Vega'\ncolour = 'red'\n", "unknown keys ['colour']"),
    ("[[target]]\nstar = 'Vega'\nwindow = ['2024-05-19T01:00:00Z', '2024-05-18T01:00:00Z']\n",
     "window ends before it starts"),
    ("[[target]]\ntle_file = 'nowhere.tle'\nsat = 'ISS'\n", "no such file"),
    ("[[target]]\ntle_file = '/dev/zero'\nsat = 'ISS'\n",
     "tle_file '/dev/zero': /dev/zero is a character device, not a regular file"),
    ("[[target]]\ntle_file = '.'\nsat = 'ISS'\n", "is a directory, not a regular file"),
    ("[[target]]\nradec = 'up there'\n", "#1"),
    ("[[target]]\nstar = 'Vega'\nrepeats = 1.5\n", "repeats = 1.5"),
    ("[[target]]\nstar = 'Vega'\naz_windows_deg = [[10]]\n", "az_windows_deg entry [10]"),
    ("[[target]]\nstar = 'Vega'\nexposures = 4\n", "exposures and exposure_s go together"),
    ("[[target]]\nstar = 'Nostar'\n", "Nostar"),
    ("[target\n", "not valid TOML"),
    ("[program]\nname = 'empty'\n", "no [[target]] tables"),
    ("[[target]]\nstar = 'Vega'\n[[target]]\nstar = 'Vega'\n", "two targets are called"),
])
def test_a_wrong_program_file_is_refused_with_where_and_what(tmp_path, text, expected):
    prog = tmp_path / "bad.toml"
    prog.write_text(text)
    result = runner.invoke(app, ["plan", str(prog), "--night", "2024-05-18"])
    assert result.exit_code == 2, result.output
    assert expected in result.output
    if expected != "Nostar":  # a name the catalog lacks is found when the sky is computed
        assert str(prog) in result.output


@pytest.mark.parametrize("args", [
    ["--night", "2024-02-30"],
    ["--from", "2024-05-18T20:00:00Z"],
    ["--from", "2024-05-18T23:00:00Z", "--to", "2024-05-18T20:00:00Z"],
    ["--night", "2024-05-18", "--from", "2024-05-18T20:00:00Z", "--to",
     "2024-05-18T23:00:00Z"],
    [],
])
def test_a_wrong_window_is_refused_as_json_too(args):
    result = runner.invoke(app, ["plan", EXAMPLE, *args, "--json"])
    assert result.exit_code == 2, result.output
    doc = json.loads(result.stdout)
    assert doc["error"]["code"] == "bad_input" and doc["error"]["message"]


def test_a_missing_program_file_says_so():
    result = runner.invoke(app, ["plan", "no/such/program.toml", "--night", "2024-05-18"])
    assert result.exit_code == 2
    assert "cannot read program no/such/program.toml" in result.output
