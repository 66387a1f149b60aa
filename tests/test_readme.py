"""The README is a front page (at most 250 lines) whose headline table says what the stored default campaign
says (``docs/data/campaign-default.json``: the range over the seeds, per specimen mode) beside the paper's bounds
(``twin.experiments.campaign.bound``), and whose links reach files that exist."""

from __future__ import annotations

import json
import re
from pathlib import Path

from twin.experiments.campaign import bound

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()

#: README row -> the campaign's metric (the same words as scripts/make_results.py's, written out again here so
#: that a row that names another metric fails)
ROWS = {"true mean error, transient": "true_mean_error_transient_max",
        "mean error (estimated), transient": "mean_error_transient_max",
        "true mean error, steady": "true_mean_error_steady_max",
        "mean error (estimated), steady": "mean_error_steady_max",
        "TC4 error, transient": "tc4_error_transient_max", "TC4 error, steady": "tc4_error_steady_max",
        "true inhomogeneity, steady": "true_inhomogeneity_steady",
        "inhomogeneity (estimated), steady": "inhomogeneity_steady"}


def _table(text: str, after: str) -> dict[str, list[str]]:
    """The first markdown table after the line ``after``: {first cell: the other cells}."""
    lines = text.split(after, 1)[1].splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("| "))
    rows = {}
    for line in lines[start:]:
        if not line.startswith("|"):
            break
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        rows[cells[0]] = cells[1:]
    return rows


def _range(cell: str) -> tuple[float, float]:
    lo, hi = re.fullmatch(r"([\d.]+) - ([\d.]+) %( ✗)?", cell).group(1, 2)
    return float(lo), float(hi)


def test_the_readme_is_a_front_page() -> None:
    assert len(README.splitlines()) <= 250
    for target in re.findall(r"\]\(([^)#:]+)(?:#[^)]*)?\)", README):  # relative links (not http:, mailto:)
        assert (REPO / target).exists(), target


def test_headline_table_summarises_the_default_campaign() -> None:
    readme = _table(README, "## Results")
    assert set(readme) == set(ROWS) | {"metric", "---"}, sorted(readme)
    campaign = json.loads((REPO / "docs" / "data" / "campaign-default.json").read_text())["campaign"]
    assert campaign["seeds"] == [0, 1, 2, 3, 4] and len(campaign["experiments"]) == 6
    for row, key in ROWS.items():
        paper_fixed, paper_osc, fixed, osc = readme[row]
        for mode, cell, paper in (("fixed", fixed, paper_fixed), ("oscillating", osc, paper_osc)):
            # from the seeds' own metrics, of the three experiments (TC4 places) of this mode
            values = [100 * s["metrics"][key] for e in campaign["experiments"]
                      if e["oscillation"] == (mode == "oscillating") for s in e["seeds"]]
            assert len(values) == 15, (row, mode)
            assert _range(cell) == (round(min(values), 2), round(max(values), 2)), (row, mode)
            limit = bound(key, mode)
            assert float(paper.strip("()").removesuffix(" %")) == round(100 * limit, 2), (row, mode)
            assert cell.endswith("✗") == (max(values) > 100 * limit), (row, mode)  # marked where the worst seed fails


def test_the_readmes_tc_placement_figures_are_the_stored_studys(load_script) -> None:
    # issue 25: "the README says whether the recommendation pays and by how much" - its figures are those of the
    # stored study (docs/figures/place-tcs/study.json, scripts/place_tcs_study.py), and so is the docs' table
    study = json.loads((REPO / "docs" / "figures" / "place-tcs" / "study.json").read_text())
    seeds = " and ".join(str(s) for s in study["seeds"])
    assert f"mean over seeds {seeds})" in README
    f = study["furnaces"]

    def mean_max(furnace: str, name: str) -> str:
        runs = f[furnace]["runs"][name]
        return f"{100 * sum(r['field_estimation_error_steady_max'] for r in runs) / len(runs):.2f} %"

    assert (f"is {mean_max('default', 'recommended')}\nwith the recommended positions against "
            f"{mean_max('default', 'paper')} with the paper's on `default`, and {mean_max('banded', 'recommended')} "
            f"against {mean_max('banded', 'paper')} on\n`banded`") in README
    info = f["default"]["information"]
    assert f"({info['recommended']:.0f}\nnats against {info['paper']:.0f} for the paper's" in README
    # "it does not pay": the recommended positions are not better on either furnace
    for k in ("default", "banded"):
        assert float(mean_max(k, "recommended")[:-2]) >= float(mean_max(k, "paper")[:-2]), k
    assert "it does not pay" in README
    docs = (REPO / "docs" / "uncertainty.md").read_text()
    mark = load_script("place_tcs_study").MARK
    assert docs.split(mark)[1].strip() == load_script("place_tcs_study").table(study).strip()
