"""Names from outside (programs, TLE files, servers) are printed with their control and
bidirectional characters escaped, and every other character as it is."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from typer.testing import CliRunner

from virtualstar.cli.main import app
from virtualstar.cli.plan import left_out_summary
from virtualstar.display import safe_text

runner = CliRunner()
HOSTILE = "Vega\u202eagev\x00\n\x1b[2J\u2028x"  # RTL override, NUL, newline, clear screen
ESCAPED = "Vega\\u202eagev\\x00\\n\\x1b[2J\\u2028x"


@pytest.mark.parametrize(("raw", "shown"), [
    (HOSTILE, ESCAPED),
    ("M 31 — Andromède, 仙女座", "M 31 — Andromède, 仙女座"),  # letters stay as they are
    ("\t\r\x7f\x9b\u200b\u200f\u2066\ufeff", "\\t\\r\\x7f\\x9b\\u200b\\u200f\\u2066\\ufeff"),
])
def test_safe_text_escapes_controls_and_invisible_formatting_only(raw, shown):
    assert safe_text(raw) == shown


def _program(tmp_path: Path) -> Path:
    prog = tmp_path / "hostile.toml"
    name = json.dumps(HOSTILE)  # a TOML basic string takes JSON's escapes
    prog.write_text(f"[[target]]\nname = {name}\nstar = 'Vega'\nduration_s = 600\n"
                    "[[target]]\nname = \"never\u202e\"\nradec = '0 -89'\nmin_el_deg = 30\n")
    return prog


def test_vs_plan_prints_hostile_target_names_escaped_and_keeps_them_in_json(tmp_path):
    prog = _program(tmp_path)
    table = runner.invoke(app, ["plan", str(prog), "--night", "2024-05-18"])
    assert table.exit_code == 0, table.output
    for bad in ("\u202e", "\x00", "\x1b", "\u2028"):
        assert bad not in table.stdout
    assert "Vega\\u202eagev\\x00" in table.stdout and "left out: never\\u202e:" in table.stdout
    doc = json.loads(runner.invoke(app, ["plan", str(prog), "--night", "2024-05-18",
                                         "--json"]).stdout)
    assert {b["target"] for b in doc["blocks"]} == {HOSTILE}  # the data keeps the name


def test_vs_where_prints_a_hostile_tle_name_escaped(tmp_path):
    from catalogs import load_tle_file, sample_tle_path

    rec = load_tle_file(sample_tle_path("stations"))[0]
    tle = tmp_path / "hostile.tle"
    tle.write_text(f"ISS\u202e\x1b[31m\n{rec.line1}\n{rec.line2}\n", encoding="utf-8")
    result = runner.invoke(app, ["where", "--tle", str(tle), "--at", "2024-05-18T20:00:00Z"])
    assert result.exit_code == 0, result.output
    assert "\u202e" not in result.stdout and "\x1b" not in result.stdout
    assert "ISS\\u202e\\x1b[31m from " in result.stdout


def test_many_left_out_targets_are_summarised_by_reason():
    left = ([{"target": f"N{i}", "reason": "never above 30° and the horizon profile during "
              "the night"} for i in range(700)]
            + [{"target": f"T{i}", "reason": f"no free time left where it can be observed "
                f"(20:0{i % 10}–21:00 UTC, starts): taken by A{i}"} for i in range(300)]
            + [{"target": "S\u202e", "reason": "the pass at 2024-05-18T20:01:02Z overlaps B"}])
    lines = left_out_summary(left)
    assert lines[0].startswith("left out: 1001 targets")
    assert lines[1] == ("     700 never above 30° and the horizon profile during the night: "
                        "N0, N1, N2, N3 and 696 more")
    assert lines[2] == ("     300 no free time left where it can be observed: T0, T1, T2, T3 "
                        "and 296 more")
    assert lines[3] == "       1 the pass at … overlaps B: S\u202e"  # escaped when printed
    assert len(lines) == 4


def test_vs_plan_summarises_left_out_targets_at_a_terminal_and_lists_them_when_piped(tmp_path):
    prog = tmp_path / "many.toml"
    prog.write_text("[[target]]\nstar = 'Vega'\n" + "".join(
        f"[[target]]\nname = 'south{i}'\nradec = '{i * 10} -85'\n" for i in range(30)))
    args = ["plan", str(prog), "--night", "2024-05-18"]
    piped = runner.invoke(app, args)
    assert piped.exit_code == 0
    assert sum(x.startswith("left out: south") for x in piped.stdout.splitlines()) == 30
    terminal = runner.invoke(app, args, env={"FORCE_COLOR": "1", "COLUMNS": "200"})
    assert terminal.exit_code == 0
    assert "left out: 30 targets" in terminal.stdout
    assert "30 never above 30° and the horizon profile during the night: south0, south1, " \
        "south2, south3 and 26 more" in terminal.stdout
    assert "left out: south29" not in terminal.stdout
