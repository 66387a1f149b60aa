"""``run_wall_s`` of ``furnace-twin bench``: a run that fails is an error, never a (short) wall time."""

from __future__ import annotations

import os

import pytest

from benchmarks.bench import run_wall_seconds


def test_a_failed_run_raises_with_its_message(tmp_path) -> None:
    bad = tmp_path / "furnace.toml"
    bad.write_text("[specimen\n")  # not TOML: the command exits 2 within a second, having run nothing
    with pytest.raises(RuntimeError, match="failed \\(2\\)"):
        run_wall_seconds(str(bad), repeats=1)


def test_a_run_without_its_figures_is_not_timed(tmp_path, monkeypatch) -> None:
    """A command that exits 0 but left out a file of the run (here its figures) would time less than a user waits."""
    import subprocess

    def without_figures(cmd, **kwargs):
        out = cmd[cmd.index("--out") + 1]
        os.makedirs(out)
        for name in ("metrics.json", "timeseries.npz", "recording.rrd"):
            open(os.path.join(out, name), "w").close()
        return subprocess.CompletedProcess(cmd, 0, "", "")

    monkeypatch.setattr("benchmarks.bench.subprocess.run", without_figures)
    with pytest.raises(RuntimeError, match="did not write signals.png, field.png"):
        run_wall_seconds(None, repeats=1)
