"""The figures of docs/opcua.md's "The transport tested exactly" (the 1.301 % CI run explained) from
``scripts/opcua_stall.py``: the bold ones of its table, recomputed in process (small furnace, about 1 s each)."""

from __future__ import annotations

import re
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "scripts"))

from opcua_stall import steady_error  # noqa: E402


def readme_row() -> list[str]:
    text = (REPO / "docs" / "opcua.md").read_text()
    row = re.search(r"^\| steady mean error, % of the setpoint \|(.+)\|$", text, re.M)
    assert row is not None, "docs/opcua.md lost the stall table"
    return [c.strip() for c in row.group(1).split("|")]


def test_the_readme_stall_figures(small_radiation) -> None:
    cells = readme_row()  # none, 1.0, 1.2, 1.3, 1.4 s, one-sample delay
    bold = {i: float(c.strip("*")) for i, c in enumerate(cells) if c.startswith("**")}
    assert set(bold) == {0, 3, 5}, cells
    got = {0: steady_error(small_radiation), 3: steady_error(small_radiation, t_a=5.0, d=1.3),
           5: steady_error(small_radiation, delay=True)}
    for i, value in got.items():
        assert 100 * value == pytest.approx(bold[i], abs=0.0015), (i, 100 * value)
    # the mechanism: a stall shorter than the watchdog's second changes nothing that matters, a longer one cuts
    # the heat-up and the steady error; a late command goes the other way
    assert got[3] < got[0] - 0.003 < got[5] - 0.003
