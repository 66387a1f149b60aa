"""The campaign report's coverage table (issue 25): is the reported band true, per experiment over its seeds.

Hand-made experiments with known per-seed coverages; the figures the table must show are worked out here
from the issue's bar (steady 90-99 %, transient >= 85 %), not taken from the function.
"""

from __future__ import annotations

import numpy as np

from twin.estimation.consistency import coverage
from twin.experiments.campaign import campaign_report, coverage_table


def _exp(name: str, steady: list[float | None], transient: list[float | None], nees=None, nis=None) -> dict:
    seeds = []
    for i, (s, t) in enumerate(zip(steady, transient, strict=True)):
        m = {"coverage_2sigma_steady": s, "coverage_2sigma_transient": t}
        if nees is not None:
            m["nees_mean"] = nees[i]
        if nis is not None:
            m["nis_mean"] = nis[i]
        seeds.append({"seed": i, "metrics": m})
    return {"name": name, "seeds": seeds, "metrics": {}, "oscillation": name.startswith("osc"), "model_error": {}}


def _row(table: str, name: str) -> list[str]:
    line = next(r for r in table.splitlines() if r.startswith(f"| {name} |"))
    return [c.strip() for c in line.strip("|").split("|")]


def test_a_row_gives_each_seed_the_mean_the_count_in_band_and_the_smallest_transient() -> None:
    # seeds 0.998, 0.92, 0.87: mean 0.9293 (in the band), 1 of 3 in 90-99 % (0.998 over, 0.87 under)
    e = _exp("oscillating_tc4_0.5", [0.998, 0.92, 0.87], [0.95, 0.88, 0.91], nees=[0.4, 1.7, 1.0],
             nis=[1.02, 1.13, 1.05])
    cells = _row(coverage_table([e]), "oscillating_tc4_0.5")
    assert cells[1] == "99.8, 92.0, 87.0"
    assert cells[2] == "92.9"  # no mark: inside 90-99 %
    assert cells[3] == "1 of 3"
    assert cells[4] == "88.0"  # the smallest transient, not the mean (91.3) nor the first
    assert cells[5] == "0.40 - 1.70"
    assert cells[6] == "1.02 - 1.13"


def test_the_mean_is_marked_outside_the_band_on_either_side_and_a_low_transient_too() -> None:
    over = _exp("over", [0.999, 0.995], [0.97, 0.96])  # mean 99.7 %: over-confident the other way, too wide
    under = _exp("under", [0.86, 0.92], [0.90, 0.84])  # mean 89.0 %; a transient of 84 % < 85 %
    edge = _exp("edge", [0.90, 0.99], [0.85, 0.85])  # the band's and the transient's edges are inside
    table = coverage_table([over, under, edge])
    assert _row(table, "over")[2] == "99.7 ✗" and _row(table, "over")[3] == "0 of 2"
    assert _row(table, "under")[2] == "89.0 ✗" and _row(table, "under")[4] == "84.0 ✗"
    assert _row(table, "edge")[2] == "94.5" and _row(table, "edge")[3] == "2 of 2" and _row(table, "edge")[4] == "85.0"


def test_missing_and_nan_coverages_are_left_out_and_a_campaign_without_any_gets_no_section() -> None:
    e = _exp("fixed", [0.95, None, float("nan")], [0.9, None, 0.8])
    cells = _row(coverage_table([e]), "fixed")
    assert cells[1] == "95.0" and cells[3] == "1 of 1"
    assert cells[4] == "80.0 ✗" and cells[5] == "n/a"
    none = _exp("no_truth", [None, float("nan")], [None, None])
    assert coverage_table([none]) == ""
    result = {"experiments": [none], "seeds": [0, 1], "truth": "model"}
    assert "Is the reported band true?" not in campaign_report(result, 30.0)
    result["experiments"] = [e]
    assert "Is the reported band true?" in campaign_report(result, 30.0)


def test_the_mean_over_seeds_is_the_pooled_share_when_the_seeds_have_the_same_cells_and_samples() -> None:
    # what the table's "mean over the seeds" stands for: three runs of 40 samples x 12 cells each, the pooled
    # share of all their entries (the oracle) against the mean of the per-run shares the campaign stores
    rng = np.random.default_rng(7)
    errs = [rng.normal(o, 1.0, (40, 12)) for o in (-0.8, 0.1, 1.5)]
    sigma = np.full((40, 12), 0.9)
    per_run = [coverage(e, sigma) for e in errs]
    pooled = coverage(np.concatenate(errs), np.concatenate([sigma] * 3))
    e = _exp("osc", per_run, [0.9] * 3)
    assert _row(coverage_table([e]), "osc")[2].split()[0] == f"{100 * pooled:.1f}"
