"""The campaign command on the small furnace with a shortened transition (t_E = 10 s)."""

import json

import numpy as np
import pytest

from twin.config import load_config, small_config
from twin.runs.campaign import PAPER, TC4_POSITIONS, campaign_scenarios, campaign_table, run_campaign
from twin.runs.metrics import METRIC_KEYS, compute_metrics


def test_scenarios_are_the_papers_six():
    cfg = load_config()
    sc = campaign_scenarios(cfg)
    assert len(sc) == 6
    osc = [s for _, s in sc if s.oscillation.enabled]
    assert len(osc) == 3
    # section 5.2: eta = 3 L_h sin(2 pi t / Pi), Pi = 0.15 t_E
    assert all(s.oscillation.amplitude == 3 * cfg.lamps.horizontal.pitch for s in osc)
    assert all(s.oscillation.period == 0.15 * s.reference.t_E for s in osc)
    assert sorted({s.tc4 for _, s in sc}) == sorted(TC4_POSITIONS)
    assert all(s.duration == 2 * s.reference.t_E for _, s in sc)


def test_short_campaign_writes_everything(tmp_path, small_radiation):
    cfg = small_config()
    result = run_campaign(cfg, tmp_path, t_E=10.0, radiation=small_radiation)
    assert result["paper"] == PAPER
    names = [e["name"] for e in result["experiments"]]
    assert len(names) == 6 and len(set(names)) == 6
    amplitude = 3 * cfg.lamps.horizontal.pitch  # section 5.2: 3 L_h (0.048 m, inside eta_max)
    for e in result["experiments"]:
        folder = tmp_path / e["name"]
        assert e["out"] == str(folder)
        saved = json.loads((folder / "metrics.json").read_text())
        with np.load(folder / "timeseries.npz") as npz:
            ts = dict(npz)
        assert ts["t"][-1] == 20.0
        # the reported figures are those of the stored run (recomputed from its time series)
        again = compute_metrics(ts)
        for k, v in saved.items():
            assert again[k] == pytest.approx(v, rel=1e-12, abs=1e-15), (e["name"], k)
        # the oscillating runs move by 3 L_h sin(2 pi t / (0.15 t_E)); sampled at 0.1 s (1/15 of the
        # 1.5 s period) the largest |eta| seen is within cos(2 pi 0.05 / 1.5) = 97.8 % of the amplitude
        if e["oscillation"]:
            assert 0.975 * amplitude <= np.abs(ts["eta"]).max() <= amplitude * (1 + 1e-12)
        else:
            assert not np.any(ts["eta"])
        assert np.allclose(ts["tc_positions"][3] / [cfg.specimen.length, cfg.specimen.width], e["tc4"])
    assert json.loads((tmp_path / "campaign.json").read_text())["experiments"] == result["experiments"]
    # the table puts each experiment's figure, in percent with two decimals, in its metric's row
    rows = {line.split("|")[1].strip(): [c.strip() for c in line.split("|")[2:-1]]
            for line in (tmp_path / "campaign.md").read_text().splitlines() if line.startswith("| ")}
    for key in METRIC_KEYS:
        for cell, e in zip(rows[key][2:], result["experiments"], strict=True):
            v = e["metrics"][key]
            assert cell == ("n/a" if v is None else f"{100 * v:.2f} %"), (key, e["name"])
    assert rows["inhomogeneity_steady"][:2] == ["4.00 %", "2.00 %"]  # the paper's column (section 5.3)
    assert (tmp_path / "homogeneity.png").stat().st_size > 10_000
    # one row per metric of product.md, below a header and a separator line
    assert campaign_table(result["experiments"]).count("\n") == 2 + len(METRIC_KEYS) - 1
