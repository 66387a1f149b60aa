"""Command-line errors are one clear line and exit status 2, never a traceback."""

import subprocess
import sys

import pytest

from furnace_twin.cli import build_parser, main


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
    out = subprocess.run([sys.executable, "-m", "furnace_twin", "--help"], capture_output=True, text=True, check=True)
    assert "campaign" in out.stdout and "bench" in out.stdout


def test_run_and_simulate_check_the_scenario_against_the_furnace(tmp_path, capsys):
    """A furnace whose eta_max (30 mm) is below the default amplitude (3 L_h = 48 mm): an amplitude above it
    is a clear error before any run; a scenario that leaves the amplitude out takes the furnace's."""
    from twin.config import load_config
    from twin.limits import furnace_name, scenario_limits
    from twin.user_files import load_scenario

    low = tmp_path / "low_stroke.toml"
    low.write_text('base = "default"\n[oscillation]\neta_max = 0.03\n')
    sc = tmp_path / "s.json"
    sc.write_text('{"oscillation": {"enabled": true, "amplitude": 0.048}}')
    assert main(["--config", str(low), "run", "--scenario", str(sc), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "oscillation.amplitude: at most 0.03 m (eta_max of furnace 'low_stroke'), got 0.048 m" in err
    assert "Traceback" not in err and not (tmp_path / "o").exists()
    assert main(["--config", str(low), "simulate", "--oscillate", "--amplitude", "0.04",
                 "--out", str(tmp_path / "sim")]) == 2
    assert "--amplitude: at most 0.03 m" in capsys.readouterr().err
    cfg = load_config(low)
    left_out = load_scenario(None, scenario_limits(cfg, furnace_name(cfg, low)), oscillate=True)
    assert left_out.oscillation.enabled and left_out.oscillation.amplitude == 0.03


def test_campaign_options(capsys):
    p = build_parser()
    a = p.parse_args(["campaign", "--config", "banded", "--seeds", "3", "--truth", "shared"])
    assert (a.config, a.seeds, a.truth) == ("banded", 3, "shared")  # --config also after the command
    a = p.parse_args(["--config", "banded", "campaign"])
    assert (a.config, a.seeds, a.truth) == ("banded", 5, "independent")  # product.md: 5 seeds, honest truth
    assert p.parse_args(["campaign"]).config is None
    assert main(["campaign", "--seeds", "0"]) == 2
    assert "--seeds must be >= 1" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        p.parse_args(["campaign", "--truth", "model"])
