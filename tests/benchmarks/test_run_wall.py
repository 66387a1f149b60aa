"""``run_wall_s`` of ``furnace-twin bench``: a run that fails is an error, never a (short) wall time."""

from __future__ import annotations

import pytest

from benchmarks.bench import run_wall_seconds


def test_a_failed_run_raises_with_its_message(tmp_path) -> None:
    bad = tmp_path / "furnace.toml"
    bad.write_text("[specimen\n")  # not TOML: the command exits 2 within a second, having run nothing
    with pytest.raises(RuntimeError, match="failed \\(2\\)"):
        run_wall_seconds(str(bad), repeats=1)
