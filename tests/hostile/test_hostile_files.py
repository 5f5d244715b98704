"""Files named by users and clients: regular files only, size-capped, never a blocking open."""

from __future__ import annotations

import os

import pytest
from typer.testing import CliRunner

from virtualstar.cli.main import app
from virtualstar.files import FileRefused, read_text_file

runner = CliRunner()


@pytest.fixture
def specials(tmp_path):
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)  # nobody writes: a plain open() would wait for ever
    big = tmp_path / "big.txt"
    big.write_bytes(b"x" * 2000)
    binary = tmp_path / "binary.txt"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    return {"fifo": fifo, "dir": tmp_path, "zero": "/dev/zero", "big": big, "binary": binary}


def test_only_regular_text_files_within_the_cap_are_read(specials, tmp_path):
    good = tmp_path / "good.txt"
    good.write_text("Vega\n")
    assert read_text_file(good, max_bytes=100) == "Vega\n"
    for key, words in [("fifo", "FIFO"), ("dir", "directory"), ("zero", "character device"),
                       ("big", "2000 bytes, more than the 1000"), ("binary", "not UTF-8")]:
        with pytest.raises(FileRefused, match=words):
            read_text_file(specials[key], max_bytes=1000, what="thing")
    with pytest.raises(FileRefused, match="No such file"):
        read_text_file(tmp_path / "missing", max_bytes=10)


def test_a_name_holding_a_nul_is_refused_as_such_by_both_readers(tmp_path):
    from catalogs.tle import ElementFileError, read_element_text

    with pytest.raises(FileRefused, match="NUL character"):
        read_text_file(f"{tmp_path}/plan\x00.json", max_bytes=100)
    with pytest.raises(ElementFileError, match="NUL character"):
        read_element_text(f"{tmp_path}/stations\x00.tle")


@pytest.mark.parametrize("command", [["run", "{path}"], ["track", "--tle", "{path}"]])
def test_the_cli_refuses_a_fifo_for_a_plan_or_a_tle_at_once(specials, command):
    args = [a.format(path=specials["fifo"]) for a in command]
    result = runner.invoke(app, [*args, "--server", "ws://127.0.0.1:9"])
    assert result.exit_code == 2, result.output
    assert "FIFO" in result.output + (result.stderr or "")
