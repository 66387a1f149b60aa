"""The README is a front page (at most 250 lines) whose headline table agrees with the campaign table it
summarises (``docs/estimation.md``, the ``default`` furnace's range over the seeds) and with the paper's bounds
(``twin.experiments.campaign.bound``), and whose links reach files that exist."""

from __future__ import annotations

import re
from pathlib import Path

from twin.experiments.campaign import bound

REPO = Path(__file__).resolve().parents[1]
README = (REPO / "README.md").read_text()

#: README row -> the campaign's metric
ROWS = {"mean error, transient": "mean_error_transient_max", "mean error, steady": "mean_error_steady_max",
        "TC4 error, transient": "tc4_error_transient_max", "TC4 error, steady": "tc4_error_steady_max",
        "inhomogeneity, steady": "inhomogeneity_steady", "true inhomogeneity, steady": "true_inhomogeneity_steady"}


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
    docs = _table((REPO / "docs" / "estimation.md").read_text(), "#### `default`")
    for row, key in ROWS.items():
        paper_fixed, paper_osc, fixed, osc = readme[row]
        for mode, cell, columns, paper in (("fixed", fixed, docs[key][:3], paper_fixed),
                                           ("oscillating", osc, docs[key][3:], paper_osc)):
            ranges = [_range(c) for c in columns]
            lo, hi = min(r[0] for r in ranges), max(r[1] for r in ranges)  # over the three TC4 places
            assert _range(cell) == (lo, hi), (row, mode)
            limit = bound(key, mode)
            assert float(paper.strip("()").removesuffix(" %")) == round(100 * limit, 2), (row, mode)
            assert cell.endswith("✗") == (hi > 100 * limit), (row, mode)  # marked where the worst seed fails
