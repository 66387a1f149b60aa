"""``furnace-twin study``: the --json object of product.md on a separately started Dask cluster
(``dask scheduler`` + ``dask worker`` processes), and clear errors with exit status 2."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from furnace_twin.cli import build_parser, main
from twin.config import small_config, small_config_toml

DASK = str(Path(sys.executable).with_name("dask"))


def _free_port() -> int:
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@pytest.fixture
def small_furnace(tmp_path) -> Path:
    """``small_config()`` as a furnace file (same digest, so the test radiation cache serves it)."""
    f = tmp_path / "small.toml"
    f.write_text(small_config_toml())
    from twin.config import load_config

    assert load_config(f).digest() == small_config().digest()
    return f


@pytest.fixture
def dask_cluster(radiation_cache):
    """A scheduler and one worker process started with the dask CLI, on loopback; stopped by pid."""
    port = _free_port()
    address = f"tcp://127.0.0.1:{port}"
    procs = [subprocess.Popen([DASK, "scheduler", "--host", "127.0.0.1", "--port", str(port), "--no-dashboard"],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)]
    time.sleep(1.0)
    procs.append(subprocess.Popen([DASK, "worker", address, "--nworkers", "1", "--nthreads", "1", "--host",
                                   "127.0.0.1", "--no-dashboard"],
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
    try:
        yield address
    finally:
        for p in reversed(procs):
            os.killpg(p.pid, signal.SIGTERM)
            try:
                p.wait(15)
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def test_study_json_on_a_separately_started_cluster(tmp_path, small_furnace, dask_cluster, capsys):
    study = tmp_path / "s.toml"
    study.write_text('furnace = "small.toml"\nname = "cli"\n[base]\nduration = 12.0\n'
                     "reference = {setpoint = 900.0, t_E = 6.0}\n[grid]\ntc_noise = [0.5, 1.0]\n")
    out = tmp_path / "out"
    assert main(["study", str(study), "--out", str(out), "--scheduler", dask_cluster, "--json",
                 "--keep-series"]) == 0
    result = json.loads(capsys.readouterr().out)
    # product.md: {"cases": [{"key", "params", "status", "metrics", "error", "out"}], "computed", "skipped",
    # "failed", "workers", "wall_s", "results"}
    assert {"cases", "computed", "skipped", "failed", "workers", "wall_s", "results"} <= set(result)
    assert (result["computed"], result["skipped"], result["failed"], result["workers"]) == (2, 0, 0, 1)
    assert result["results"] == str(out / "results.parquet") and Path(result["results"]).is_file()
    assert [c["params"] for c in result["cases"]] == [{"tc_noise": 0.5}, {"tc_noise": 1.0}]
    for c in result["cases"]:
        assert c["status"] == "done" and c["error"] is None
        assert set(c["metrics"]) >= {"inhomogeneity_steady", "tc4_error_steady_max"}
        assert (Path(c["out"]) / "timeseries.npz").is_file()
    assert (out / "study.md").read_text().startswith("# Study: cli")
    # the same command again finds both cases done
    assert main(["study", str(study), "--out", str(out), "--scheduler", dask_cluster, "--json",
                 "--keep-series"]) == 0
    again = json.loads(capsys.readouterr().out)
    assert (again["computed"], again["skipped"]) == (0, 2)
    assert [c["status"] for c in again["cases"]] == ["skipped", "skipped"]


def test_bad_study_file_exits_2_with_the_reason(tmp_path, capsys):
    study = tmp_path / "s.toml"
    study.write_text('[grid]\n"oscillation.perod" = [6.0]\n')
    assert main(["study", str(study), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert "oscillation.perod" in err and "Traceback" not in err
    study.write_text('furnace = "nowhere.toml"\n[grid]\ntc_noise = [1.0]\n')
    assert main(["study", str(study), "--out", str(tmp_path / "o")]) == 2
    assert "nowhere.toml" in capsys.readouterr().err
    assert main(["study", str(tmp_path / "missing.toml")]) == 2
    assert "cannot read" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()  # nothing is started for a bad study


def test_unreachable_scheduler_exits_2(tmp_path, capsys, monkeypatch):
    import twin.studies.cluster as cluster
    import twin.studies.command as command

    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 1.0)

    def trace(_cfg):  # the wrong address is said before a missing table is traced (60 s on 2 idle cores)
        raise AssertionError("radiation tables traced before the scheduler was asked")

    monkeypatch.setattr(command, "_ensure_radiation_tables", trace)
    study = tmp_path / "s.toml"
    study.write_text("[base]\nduration = 12.0\n[grid]\ntc_noise = [1.0]\n")
    address = f"tcp://127.0.0.1:{_free_port()}"
    assert main(["study", str(study), "--out", str(tmp_path / "o"), "--scheduler", address]) == 2
    assert "cannot reach the Dask scheduler" in capsys.readouterr().err


@pytest.mark.parametrize("argv", [["study", "f.toml", "--workers", "0"],
                                  ["study", "f.toml", "--workers", "2", "--scheduler", "tcp://127.0.0.1:1"]])
def test_bad_options_are_argparse_errors(argv):
    with pytest.raises(SystemExit) as exc:
        build_parser().parse_args(argv)
    assert exc.value.code == 2
