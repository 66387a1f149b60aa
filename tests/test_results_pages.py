"""The documentation's results pages say what their stored campaign JSON says (``scripts/make_results.py``).

A page is the campaign's own report (``twin.experiments.campaign.campaign_report``) of the JSON in
``docs/data/``, so a figure edited in a page, a JSON changed without its page, or a page whose JSON is gone fails
here; ``python scripts/make_results.py`` writes the pages again.
"""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def make_results():
    spec = importlib.util.spec_from_file_location("make_results", REPO / "scripts" / "make_results.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules["make_results"] = module
    spec.loader.exec_module(module)
    return module


def test_every_results_page_is_what_its_json_gives(make_results) -> None:
    pages = make_results.pages()
    assert pages, "no campaign JSON in docs/data"
    for path, text in pages.items():
        assert path.is_file(), f"{path.name} missing: python scripts/make_results.py"
        assert path.read_text() == text, f"{path.name} differs from its JSON: python scripts/make_results.py"
    stored = {p.name for p in (REPO / "docs" / "results").glob("campaign-*.md")}
    assert stored == {p.name for p in pages}, "a results page without its JSON"


def test_the_readme_table_is_what_the_default_campaign_gives(make_results) -> None:
    readme = (REPO / "README.md").read_text()
    assert make_results.README_BEGIN in readme and make_results.README_END in readme
    assert make_results.readme_with_table(readme) == readme, "README table stale: python scripts/make_results.py"


def test_a_page_shows_each_experiments_worst_seed(make_results) -> None:
    # independent of the report's code: the worst over the seeds, from the seeds' own metrics in the JSON
    data = json.loads((REPO / "docs" / "data" / "campaign-small.json").read_text())
    page = (REPO / "docs" / "results" / "campaign-small.md").read_text()
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
            for line in page.split("## Range")[0].splitlines() if line.startswith("| ")}
    experiments = data["campaign"]["experiments"]
    for key in ("mean_error_steady_max", "tc4_error_steady_max", "true_inhomogeneity_steady"):
        for cell, e in zip(rows[key][2:], experiments, strict=True):
            worst = max(s["metrics"][key] for s in e["seeds"])
            assert cell.removesuffix(" ✗") == f"{100 * worst:.2f} %", (key, e["name"])


def test_check_mode_finds_a_stale_page(make_results, tmp_path, monkeypatch) -> None:
    data = json.loads((REPO / "docs" / "data" / "campaign-small.json").read_text())
    data["campaign"]["experiments"][0]["metrics"]["mean_error_steady_max"] += 0.01  # one figure moved by 1 %
    (tmp_path / "data").mkdir()
    (tmp_path / "data" / "campaign-small.json").write_text(json.dumps(data))
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / "campaign-small.md").write_text(
        (REPO / "docs" / "results" / "campaign-small.md").read_text())
    monkeypatch.setattr(make_results, "DATA", tmp_path / "data")
    monkeypatch.setattr(make_results, "PAGES", tmp_path / "results")
    assert make_results.main(["--check"]) == 1
    assert make_results.main([]) == 0 and make_results.main(["--check"]) == 0  # written again, then it agrees
