"""The documentation's results pages say what their stored campaign JSON says (``scripts/make_results.py``).

A page is the campaign's own report (``twin.experiments.campaign.campaign_report``) of the JSON in
``docs/data/``, so a figure edited in a page, a JSON changed without its page, or a page whose JSON is gone fails
here; ``python scripts/make_results.py`` writes the pages again.
"""

from __future__ import annotations

import json
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def make_results(load_script):
    return load_script("make_results")


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


def test_the_readme_coverage_table_is_the_stored_campaigns_pooled_share(make_results) -> None:
    # independent of make_results' code: the share over all seeds' cells x samples of each judged case (issue 25)
    # is the mean of the seeds' shares (equal windows), read here from the JSON; the README table must say it
    readme = (REPO / "README.md").read_text()
    block = readme.split(make_results.COVERAGE_BEGIN)[1].split(make_results.COVERAGE_END)[0]
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
            for line in block.splitlines() if line.startswith("| `")}
    assert set(rows) == {"`default`, fixed", "`default`, oscillating", "`banded`, fixed", "`banded`, oscillating"}
    for name in ("default", "banded"):
        data = json.loads((REPO / "docs" / "data" / f"campaign-{name}.json").read_text())
        for mode, osc in (("fixed", False), ("oscillating", True)):
            seeds = next(e for e in data["campaign"]["experiments"] if e["oscillation"] == osc)["seeds"]
            steady = [s["metrics"]["coverage_2sigma_steady"] for s in seeds]
            mean, each, transient = rows[f"`{name}`, {mode}"]
            assert mean == f"{100 * sum(steady) / len(steady):.1f} %"
            assert 90.0 <= float(mean.removesuffix(" %")) <= 99.0, (name, mode, "the README claims the band")
            assert each == ", ".join(f"{100 * v:.1f}" for v in steady)
            smallest = min(s["metrics"]["coverage_2sigma_transient"] for s in seeds)
            assert transient == f"{100 * smallest:.1f} %" and smallest >= 0.85, (name, mode)


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


def _campaign_folder(folder: Path, campaign: dict, t_E: float) -> Path:
    """A ``furnace-twin campaign`` folder as the store reads it: campaign.json and the report's t_E line."""
    folder.mkdir(parents=True)
    (folder / "campaign.json").write_text(json.dumps(campaign))
    (folder / "campaign.md").write_text(f"# Campaign\n\nTruth: independent; seeds 0..1; t_E = {t_E:g} s.\n")
    return folder


def _paper_of(campaign: dict) -> dict:
    """The reduced campaign as if the paper's estimator had run it: every metric 1.5 times the default's."""
    paper = json.loads(json.dumps(campaign))
    paper["estimator"] = {"name": "paper", "motion": "averaged", "calibrate": False, "shadow": None}
    for e in paper["experiments"]:
        for m in [e["metrics"], *(s["metrics"] for s in e["seeds"])]:
            for k, v in m.items():
                if isinstance(v, float):
                    m[k] = 1.5 * v
        for s in e["seeds"]:
            s["out"] = "/elsewhere/run"  # a run folder on the machine that ran it: not stored
    return paper


@pytest.fixture()
def sandbox(make_results, tmp_path, monkeypatch):
    """make_results on copies: its data, pages, docs and mkdocs.yml in tmp_path."""
    docs = tmp_path / "docs"
    (docs / "data").mkdir(parents=True)
    (docs / "results").mkdir()
    for name in make_results.DOC_PAGES:
        (docs / name).write_text((REPO / "docs" / name).read_text())
    (tmp_path / "mkdocs.yml").write_text((REPO / "mkdocs.yml").read_text())
    monkeypatch.setattr(make_results, "DATA", docs / "data")
    monkeypatch.setattr(make_results, "PAGES", docs / "results")
    monkeypatch.setattr(make_results, "MKDOCS", tmp_path / "mkdocs.yml")
    (tmp_path / "README.md").write_text((REPO / "README.md").read_text())
    monkeypatch.setattr(make_results, "README", tmp_path / "README.md")
    small = json.loads((REPO / "docs" / "data" / "campaign-small.json").read_text())
    return tmp_path, small["campaign"], float(small["t_E"])


def test_a_campaign_with_the_papers_estimator_gets_its_comparison_page_links_and_nav(make_results, sandbox) -> None:
    root, campaign, t_E = sandbox
    both = {**campaign, "paper_estimator": _paper_of(campaign)}  # what --estimator both writes
    folder = _campaign_folder(root / "run", both, t_E)
    command = "furnace-twin --config banded campaign --estimator both --out DIR"
    assert make_results.main(["--store", "banded", str(folder), command]) == 0
    stored = json.loads((root / "docs" / "data" / "campaign-banded.json").read_text())
    assert all("out" not in s for e in stored["campaign"]["paper_estimator"]["experiments"] for s in e["seeds"])
    page = (root / "docs" / "results" / "campaign-banded.md").read_text()
    section = page.split("## The paper's estimator beside the default")[1]
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
            for line in section.splitlines() if line.startswith("| ")}
    # independent of the report's code: each cell is paper's worst seed -> default's worst seed, in %
    for cell, e, p in zip(rows["field_estimation_error_steady_max"], campaign["experiments"],
                          both["paper_estimator"]["experiments"], strict=True):
        worst = [max(s["metrics"]["field_estimation_error_steady_max"] for s in x["seeds"]) for x in (p, e)]
        assert cell == f"{100 * worst[0]:.2f} % -> {100 * worst[1]:.2f} %"
    # the pasted banded sections became links to the page, the default's stay (no paper's runs stored for it)
    for name in make_results.DOC_PAGES:
        text = (root / "docs" / name).read_text()
        banded = text.split("<!-- results:campaign-banded:paper -->")[1].split("<!-- /results:campaign-banded")[0]
        assert "](results/campaign-banded.md)" in banded and "|" not in banded, name
        default = text.split("<!-- results:campaign-default:paper -->")[1].split("<!-- /results:campaign-default")[0]
        assert default == (REPO / "docs" / name).read_text().split(
            "<!-- results:campaign-default:paper -->")[1].split("<!-- /results:campaign-default")[0]
    assert "- Campaign on the banded furnace: results/campaign-banded.md" in (root / "mkdocs.yml").read_text()
    assert make_results.main(["--check"]) == 0


def test_the_papers_runs_stored_afterwards_compare_against_the_stored_campaign(make_results, sandbox) -> None:
    root, campaign, t_E = sandbox
    make_results.main(["--store", "default", str(_campaign_folder(root / "a", campaign, t_E)), "furnace-twin campaign"])
    assert "beside the default" not in (root / "docs" / "results" / "campaign-default.md").read_text()
    for name in make_results.DOC_PAGES:  # no paper's runs stored yet: the pasted sections stay as they are
        assert (root / "docs" / name).read_text() == (REPO / "docs" / name).read_text(), name
    paper = _paper_of(campaign)
    wrong = {**paper, "seeds": [0, 1, 2]}
    with pytest.raises(SystemExit, match="seeds"):  # other plants: refused, nothing written
        make_results.main(["--store-paper", "default", str(_campaign_folder(root / "b", wrong, t_E)), "x"])
    with pytest.raises(SystemExit, match="estimator"):
        make_results.main(["--store-paper", "default", str(_campaign_folder(root / "c", campaign, t_E)), "x"])
    with pytest.raises(SystemExit, match="t_E"):
        make_results.main(["--store-paper", "default", str(_campaign_folder(root / "d", paper, 2 * t_E)), "x"])
    command = "furnace-twin campaign --estimator paper --out DIR"
    assert make_results.main(["--store-paper", "default", str(_campaign_folder(root / "e", paper, t_E)), command]) == 0
    page = (root / "docs" / "results" / "campaign-default.md").read_text()
    assert f"The paper's estimator: `{command}`" in page and "## The paper's estimator beside the default" in page
    assert "](results/campaign-default.md)" in (root / "docs" / "truth.md").read_text()


def test_every_results_page_is_in_the_site_nav(make_results) -> None:
    nav = (REPO / "mkdocs.yml").read_text()
    for path in make_results.pages():
        assert f"results/{path.name}" in nav, f"{path.name} not in mkdocs.yml's nav: python scripts/make_results.py"
