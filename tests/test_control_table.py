"""docs/control.md's before/after table is what the committed runs in docs/control_runs/ give
(scripts/control_table.py table), so the page cannot drift from its data."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _script():
    spec = importlib.util.spec_from_file_location("control_table", REPO / "scripts" / "control_table.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.parametrize("doc", ["docs/control.md", "README.md"])
def test_the_page_shows_the_committed_runs(doc):
    script = _script()
    page = (REPO / doc).read_text()
    shown = page.split(script.BEGIN, 1)[1].split(script.END, 1)[0].strip()
    made = script.table(REPO / "docs" / "control_runs").strip()
    assert shown == made, ("run: python scripts/control_table.py table --out docs/control_runs "
                           "--write docs/control.md README.md")
    assert made.count("\n") >= 2  # a header, its rule and at least one row of runs


def test_the_table_marks_a_bound_it_misses(tmp_path):
    """A made-up run above issue 26's transient bound of its furnace is marked (default 1 %, banded 2 %), one
    below it is not."""
    import json

    script = _script()
    for furnace, err in (("default", 0.0123), ("banded", 0.03), ("other", 0.05)):
        folder = tmp_path / furnace / "mpc"
        folder.mkdir(parents=True)
        (folder / "seed_0.json").write_text(json.dumps({"seed": 0, "true_mean_error_transient_max": err,
                                                        "controller": {}}))
    text = script.table(tmp_path)
    assert "| default | mpc | 0 | 1.23 % ✗ |" in text and "| banded | mpc | 0 | 3.00 % ✗ |" in text
    assert "| other | mpc | 0 | 5.00 % |" in text  # a furnace without bounds is not judged
    (tmp_path / "banded" / "mpc" / "seed_0.json").write_text(json.dumps({"seed": 0, "controller": {},
                                                                         "true_mean_error_transient_max": 0.0195}))
    assert "| banded | mpc | 0 | 1.95 % |" in script.table(tmp_path)
