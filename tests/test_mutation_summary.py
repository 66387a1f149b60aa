"""The mutation summary (scripts/mutation_modules.py): what docs/mutation.md shows of the cached results.

Oracle: hand-made cache files with known counts.  A current result is a row and counts in the total; a result
whose fingerprint no longer matches (its module or a selected test changed) is a row marked stale, out of the
total; a module without a result is listed as not run.
"""

from __future__ import annotations

import json


def _result(module: str, fingerprint: str, statuses: list[str]) -> dict:
    return {"module": module, "fingerprint": fingerprint, "date": "2026-12-03T10:00:00+00:00",
            "results": {f"{module}.x__mutmut_{i}": st for i, st in enumerate(statuses)}, "diffs": {}}


def test_stale_results_are_shown_marked_and_left_out_of_the_total(load_script, tmp_path, monkeypatch) -> None:
    mm = load_script("mutation_modules")
    monkeypatch.setattr(mm, "CACHE", tmp_path)
    monkeypatch.setattr(mm, "equivalents", dict)
    current, stale, missing = "twin.physics.fillet", "twin.physics.motion", "twin.model.fe"
    (tmp_path / f"{current}.json").write_text(json.dumps(
        _result(current, mm.fingerprint(current), ["killed", "killed", "killed", "survived"])))
    (tmp_path / f"{stale}.json").write_text(json.dumps(
        _result(stale, "0" * 64, ["killed", "survived", "survived", "survived", "no tests"])))
    text = mm.summary([current, stale, missing])
    rows = {line.split(" | ")[0].strip("| "): line for line in text.splitlines() if line.startswith("| ")}
    assert "| 75.0 % | 2026-12-03 |" in rows[current]
    assert "| 20.0 % | 2026-12-03 (stale) |" in rows[stale]  # as measured then, marked
    assert "| **current results** | 4 | 3 | 0 | 1 |" in rows["**current results**"]  # the stale row is not in it
    assert "**75.0 %**" in rows["**current results**"]
    assert missing not in rows
    stale_list = text.split("Stale (")[1].split("Not run (")[0]
    assert f"- {stale}" in stale_list and f"- {missing}" not in stale_list
    assert f"- {missing}" in text.split("Not run (")[1]
