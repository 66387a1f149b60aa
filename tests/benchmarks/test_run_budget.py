"""``python scripts/run_budget.py``: the wall budget of one ``furnace-twin run`` times every part it names."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

from twin.config import small_config_toml

REPO = Path(__file__).resolve().parents[2]


def test_the_budget_of_a_small_run_times_each_part(tmp_path, small_radiation, small_truth_radiation) -> None:
    cfg = tmp_path / "small.toml"
    cfg.write_text(small_config_toml())
    sc = tmp_path / "scenario.json"
    sc.write_text(json.dumps({"reference": {"setpoint": 600.0, "t_E": 4.0}, "duration": 8.0}))  # 81 samples
    done = subprocess.run(
        [sys.executable, str(REPO / "scripts" / "run_budget.py"), "--config", str(cfg), "run", "--scenario", str(sc),
         "--out", str(tmp_path / "out"), "--json"], capture_output=True, text=True, check=True,
        env={**os.environ, "FURNACE_TWIN_DATA_DIR": str(tmp_path / "data")},
    )
    rows = {}
    for line in done.stdout.splitlines()[2:]:
        part, wall, calls, _ = (c.strip() for c in line.strip("|").split("|"))
        rows[re.sub(r"^(&nbsp;)+", "", part)] = (float(wall), int(calls) if calls else None)
    total = rows.pop("the whole command (after the interpreter's start)")[0]
    assert rows["the loop's steps (with the recording's add)"][1] == 81  # every sample, each timed once
    assert rows["of which the rerun recording's add"][1] == 81
    assert rows["the final timeseries.npz (compressed, once)"][1] == 1
    assert rows["figures: waiting for the figure process"][1] == 1
    assert rows["of which the first plan (OCP with IPOPT, LQG gains)"][1] == 1
    # the twin's table once: the truth's, loaded inside open_furnace, is the furnace's row (it was counted in both)
    assert rows["radiation tables from the cache (the twin's model)"][1] == 1
    top = [k for k in rows if not k.startswith(("of which", "the loop's", "flushes", "the final", "metrics.json"))]
    assert 0 < sum(rows[k][0] for k in top) <= total  # the top-level parts do not overlap
    assert (tmp_path / "out" / "signals.png").is_file()  # the command itself ran to its end
    assert json.loads(done.stderr.strip().splitlines()[-1])["status"] == "finished"  # its --json, on stderr
