"""Command-line errors are one clear line and exit status 2, never a traceback."""

import subprocess
import sys

import pytest

from twin.cli import build_parser, main


def test_bad_config_file_exits_2(tmp_path, capsys):
    bad = tmp_path / "f.toml"
    bad.write_text("[specimen]\nlength = -1\n")
    assert main(["--config", str(bad), "precompute"]) == 2
    err = capsys.readouterr().err
    assert "specimen.length" in err and "Traceback" not in err


def test_bad_scenario_file_exits_2(tmp_path, capsys):
    sc = tmp_path / "s.json"
    sc.write_text('{"duration": -5}')
    assert main(["run", "--scenario", str(sc), "--out", str(tmp_path / "o")]) == 2
    assert "duration" in capsys.readouterr().err
    sc.write_text("{not json")
    assert main(["run", "--scenario", str(sc), "--out", str(tmp_path / "o")]) == 2
    assert "not valid JSON" in capsys.readouterr().err


@pytest.mark.parametrize("value", ["0.5", "2,0.5", "a,b"])
def test_bad_tc4_is_an_argparse_error(value):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(["run", "--tc4", value])
    assert exc.value.code == 2


def test_console_script_help_runs():
    out = subprocess.run([sys.executable, "-m", "twin.cli", "--help"], capture_output=True, text=True, check=True)
    assert "campaign" in out.stdout and "bench" in out.stdout
