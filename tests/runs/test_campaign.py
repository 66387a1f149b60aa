"""The campaign command on the small furnace with a shortened transition (t_E = 10 s)."""

import json

import numpy as np

from twin.config import load_config, small_config
from twin.runs.campaign import PAPER, TC4_POSITIONS, campaign_scenarios, campaign_table, run_campaign
from twin.runs.metrics import METRIC_KEYS


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
    result = run_campaign(small_config(), tmp_path, t_E=10.0, radiation=small_radiation)
    assert result["paper"] == PAPER
    names = [e["name"] for e in result["experiments"]]
    assert len(names) == 6 and len(set(names)) == 6
    for e in result["experiments"]:
        folder = tmp_path / e["name"]
        assert e["out"] == str(folder)
        assert json.loads((folder / "metrics.json").read_text()).keys() == e["metrics"].keys()
        with np.load(folder / "timeseries.npz") as ts:
            assert ts["t"][-1] == 20.0
            assert bool(np.any(ts["eta"] != 0)) == e["oscillation"]
            assert np.allclose(ts["tc_positions"][3] / [0.4, 0.2], e["tc4"])
    assert json.loads((tmp_path / "campaign.json").read_text())["experiments"] == result["experiments"]
    table = (tmp_path / "campaign.md").read_text()
    assert "paper fixed" in table and "inhomogeneity_steady" in table and "4.00 %" in table
    assert (tmp_path / "homogeneity.png").stat().st_size > 10_000
    # one row per metric of product.md, below a header and a separator line
    assert campaign_table(result["experiments"]).count("\n") == 2 + len(METRIC_KEYS) - 1
