"""The one-page report names a run's furnace: a simulation with its noise, seed and truth; a furnace over
OPC UA with its endpoint and the samples that came late (it has no seed, noise or truth of the twin's)."""

from __future__ import annotations

import json

import numpy as np

from twin.experiments.report import _scenario_lines
from twin.runs.metrics import windows_of


def _series(scenario: dict, tc_status: np.ndarray) -> dict:
    n = len(tc_status)
    return {"t": np.arange(n) * 0.1, "t_E": 2.0, "setpoint": 900.0, "tc_status": tc_status,
            "scenario": json.dumps(scenario)}


def test_a_furnace_over_opcua_is_named_with_its_endpoint_and_late_samples() -> None:
    status = np.zeros((10, 4), np.int8)
    status[3, 0] = 2  # sample 3: TC1 missing (late)
    status[7, :] = 2  # sample 7: nothing came
    status[8, 1] = 1  # sample 8: TC2 bad, not late
    sc = {"plant": {"kind": "opcua", "endpoint": "opc.tcp://127.0.0.1:4840/furnace-twin/"}, "speed": 1.0,
          "seed": 3, "tc_noise": 1.0, "truth": "independent", "mismatch": {"emissivity": 0.1}}
    ts = _series(sc, status)
    text = "\n".join(_scenario_lines(ts, windows_of(ts)))
    assert "furnace over OPC UA opc.tcp://127.0.0.1:4840/furnace-twin/ (no truth) · 2 late samples" in text
    assert "real time" in text
    for absent in ("seed", "TC noise", "truth independent", "mismatch", "speed"):
        assert absent not in text, absent


def test_a_simulated_furnace_is_named_with_its_noise_seed_and_truth() -> None:
    sc = {"speed": "max", "seed": 3, "tc_noise": 1.0, "truth": "shared", "mismatch": {"emissivity": 0.1}}
    ts = _series(sc, np.zeros((10, 4), np.int8))
    text = "\n".join(_scenario_lines(ts, windows_of(ts)))
    assert "TC noise 1.0 K · seed 3 · truth shared" in text and "emissivity +10 %" in text
    assert "OPC UA" not in text and "late" not in text
