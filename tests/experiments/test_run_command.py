"""``furnace-twin run`` (issue 21): its data on disk first, its figures drawn by a child process after it (and
only when asked for), an interrupted run's data kept, the compressed ``timeseries.npz`` the arrays it was given,
and a run that imports neither matplotlib nor scipy.stats on its way (about 1.6 s of the command)."""

from __future__ import annotations

import json
import subprocess
import sys
import time
import zipfile

import numpy as np
import pytest

from twin.config import small_config_toml
from twin.experiments import figures_process
from twin.experiments.figures_process import FigureProcess
from twin.runs.record import load_arrays, save_arrays

PNG = b"\x89PNG\r\n\x1a\n"
SCENARIO = {"reference": {"setpoint": 600.0, "t_E": 4.0}, "duration": 8.0}  # 81 samples of the small furnace


@pytest.fixture
def small_run(tmp_path, monkeypatch, small_radiation, small_truth_radiation):
    """``furnace-twin --config <small furnace> run --scenario <8 s> --out DIR [extra]``: (exit status, DIR)."""
    cfg = tmp_path / "small.toml"
    cfg.write_text(small_config_toml())
    sc = tmp_path / "scenario.json"
    sc.write_text(json.dumps(SCENARIO))
    monkeypatch.setenv("FURNACE_TWIN_DATA_DIR", str(tmp_path / "data"))

    def run(*extra: str):
        from furnace_twin.cli import main

        out = tmp_path / "out"
        return main(["--config", str(cfg), "run", "--scenario", str(sc), "--out", str(out), *extra]), out

    return run


def test_a_run_draws_its_figures_after_its_data(small_run) -> None:
    status, out = small_run()
    assert status == 0
    data = load_arrays(out / "timeseries.npz")
    assert len(data["t"]) == 81 and json.loads((out / "metrics.json").read_text())["status"] == "finished"
    for name in ("signals.png", "field.png"):
        png = (out / name).read_bytes()
        assert png.startswith(PNG) and len(png) > 20_000, name  # a drawn figure (90 dpi, 12 x 9 in / 15 x 4.6 in)
        # drawn from the written data, so after it
        assert (out / name).stat().st_mtime_ns >= (out / "metrics.json").stat().st_mtime_ns


def test_no_figures_writes_the_data_only(small_run) -> None:
    status, out = small_run("--no-figures")
    assert status == 0
    assert sorted(p.name for p in out.iterdir()) == ["metrics.json", "recording.rrd", "scenario.json",
                                                     "timeseries.npz"]


def test_an_interrupted_run_keeps_its_data_and_ends_its_figure_process(small_run, monkeypatch) -> None:
    """Ctrl-C half-way: exit 130, the samples so far and metrics.json (stopped) on disk, no figures, and the figure
    process (started with the command, busy importing) ended at once, not after its close timeout."""
    from twin.runs.loop import ClosedLoop

    step = ClosedLoop.step

    def interrupted(self):
        if self.j >= 40:
            raise KeyboardInterrupt
        return step(self)

    monkeypatch.setattr(ClosedLoop, "step", interrupted)
    children: list[FigureProcess] = []
    made = figures_process.FigureProcess.__init__

    def keep(self) -> None:
        made(self)
        children.append(self)

    monkeypatch.setattr(figures_process.FigureProcess, "__init__", keep)
    start = time.perf_counter()
    status, out = small_run()
    assert status == 130
    assert len(load_arrays(out / "timeseries.npz")["t"]) == 40
    assert json.loads((out / "metrics.json").read_text())["status"] == "stopped"
    assert not list(out.glob("*.png"))
    assert len(children) == 1 and children[0]._child.returncode is not None  # the child was waited for
    assert time.perf_counter() - start < 60


def test_a_figure_that_cannot_be_drawn_is_reported_not_fatal(tmp_path, caplog) -> None:
    """No ``timeseries.npz`` in the folder: ``draw`` logs why and returns no figure; it never raises or hangs."""
    start = time.perf_counter()
    with FigureProcess() as figures:
        assert figures.draw(tmp_path) == []
    assert "figures were not drawn" in caplog.text and "timeseries.npz" in caplog.text
    assert time.perf_counter() - start < figures_process.CLOSE_TIMEOUT_S


def test_closing_an_unused_figure_process_ends_it_at_once() -> None:
    """A run that fails before its figures closes the child's pipe: it ends after its import, well before the
    close timeout that would kill it."""
    figures = FigureProcess()
    start = time.perf_counter()
    figures.close()
    assert figures._child.returncode == 0
    assert time.perf_counter() - start < figures_process.CLOSE_TIMEOUT_S - 1


def test_the_compressed_series_holds_the_arrays_it_was_given(tmp_path) -> None:
    """``save_arrays`` writes its own zip (zlib level 1): np.load reads back every array to the bit (NaN payloads,
    0-d values, texts), as np.savez_compressed's file holds them, each member deflated."""
    rng = np.random.default_rng(0)
    arrays = {
        "t": np.arange(500) * 0.1, "field_hat": rng.normal(1000, 5, (500, 3, 4)).astype(np.float32),
        "nees": np.where(np.arange(500) % 7 == 0, np.nan, 1.0), "setpoint": np.array(1100.0),
        "event_text": np.array(["re-plan", "calibrated"]), "tc_status": np.zeros((500, 4), np.int8),
    }
    save_arrays(tmp_path / "ours.npz", arrays)
    np.savez_compressed(tmp_path / "numpy.npz", **arrays)
    ours, theirs = load_arrays(tmp_path / "ours.npz"), load_arrays(tmp_path / "numpy.npz")
    assert list(ours) == list(arrays)
    for k, v in arrays.items():
        assert ours[k].dtype == v.dtype and ours[k].shape == v.shape and ours[k].tobytes() == v.tobytes(), k
        assert ours[k].tobytes() == theirs[k].tobytes(), k
    with zipfile.ZipFile(tmp_path / "ours.npz") as z:
        assert {i.compress_type for i in z.infolist()} == {zipfile.ZIP_DEFLATED}
        assert z.getinfo("t.npy").compress_size < z.getinfo("t.npy").file_size
    save_arrays(tmp_path / "stored.npz", arrays, compress=False)
    with zipfile.ZipFile(tmp_path / "stored.npz") as z:
        assert {i.compress_type for i in z.infolist()} == {zipfile.ZIP_STORED}


def test_a_run_does_not_import_matplotlib_or_scipy_stats() -> None:
    """The run command's modules, in a fresh interpreter: matplotlib (the figure process's) and scipy.stats (the
    consistency bounds of a campaign) stay out; they cost about 1 s and 0.6 s of every run."""
    code = ("import sys, furnace_twin.cli, twin.experiments.run, twin.runs.loop, twin.radiation, twin.furnace.connect; "
            "print(sorted(m for m in sys.modules if m.startswith(('matplotlib', 'scipy.stats'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"


def test_a_figure_process_that_cannot_start_leaves_the_figures_to_the_run(small_run, monkeypatch, caplog) -> None:
    """No interpreter to start (an OSError from Popen): the run draws its figures itself, after its data."""

    def no_process(*args, **kwargs):
        raise OSError("no such interpreter (test)")

    monkeypatch.setattr(figures_process.subprocess, "Popen", no_process)
    status, out = small_run()
    assert status == 0 and "no figure process" in caplog.text
    assert (out / "signals.png").read_bytes().startswith(PNG) and (out / "field.png").read_bytes().startswith(PNG)
