"""The paper's estimator (EKF on the time-averaged model, eqs. 13-14) replayed on a recorded run.

    python examples/estimator_on_recorded_data.py RUN/timeseries.npz
    python examples/estimator_on_recorded_data.py          # records a short run on the small furnace first

A run's ``timeseries.npz`` holds what the furnace gave the twin (the thermocouple readings ``tc``, the lamp
inputs ``u``, the position ``eta``) and, from a simulated furnace, its true field ``field_true``.  Here a fresh
estimator reads the readings and inputs in order (update with the readings of sample j, then predict over the
sampling period with the inputs held), and its fillet mean is compared with the true field's, beside the run's
own estimate (the scenario's estimator, which fed the controller).
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

import twin
from twin.physics.fillet import Fillet
from twin.scenario import PAPER_ESTIMATOR


def record_a_run(cfg: twin.FurnaceConfig, out: Path) -> Path:
    scenario = twin.parse_scenario({"reference": {"setpoint": 1000.0, "t_E": 10.0}, "duration": 20.0})
    twin.RunSession(twin.ClosedLoop(cfg, scenario), twin.RunFolder(out)).run()
    return out / "timeseries.npz"


def replay(cfg: twin.FurnaceConfig, series: dict[str, Any]) -> np.ndarray:
    """The fillet mean of a fresh paper EKF at each recorded sample (K)."""
    scenario = twin.Scenario.model_validate_json(str(series["scenario"]))
    tables = twin.model_tables(cfg, twin.radiation_model(cfg))
    y0 = series["tc"][0][:3]
    theta0 = float(np.nanmean(y0)) if np.isfinite(y0).any() else cfg.specimen.initial_temperature
    ekf = twin.build_estimator(PAPER_ESTIMATOR, tables, scenario.oscillation, cfg, np.full(ekf_size(cfg), theta0))
    means = []
    for y, u, eta in zip(series["tc"], series["u"], series["eta"], strict=True):
        # TC1-3 feed the estimator, TC4 only checks it (paper section 5); NaN readings (gated, missing) are left out
        theta = ekf.update(y[:3]).theta
        means.append(float(ekf.model.c_m @ theta))
        ekf.predict(u, float(eta))
    return np.asarray(means)


def ekf_size(cfg: twin.FurnaceConfig) -> int:
    return len(cfg.fe.x_nodes) * len(cfg.fe.y_nodes)  # the FE nodes (twin.model.fe)


def main(argv: list[str] | None = None) -> dict[str, float]:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("series", nargs="?", type=Path, help="a run's timeseries.npz (default: record one)")
    args = ap.parse_args(argv)

    cfg = twin.small_config()
    path = args.series or record_a_run(cfg, Path(tempfile.mkdtemp(prefix="furnace-twin-recorded-")))
    series = twin.load_arrays(path)
    means = replay(cfg, series)
    # the true field is stored at the times t_field (every sample early on, later one a second)
    at = np.searchsorted(series["t"], series["t_field"])
    fillet = Fillet.of(cfg)
    truth = np.array([fillet.mean(field) for field in series["field_true"]])
    late = series["t_field"] >= 0.5 * series["t"][-1]  # the second half: the initial transient has died out
    result = {"rms_vs_truth_K": float(np.sqrt(np.mean((means[at] - truth)[late] ** 2))),
              "run_estimate_rms_vs_truth_K": float(np.sqrt(np.mean((series["T_mean_hat"][at] - truth)[late] ** 2)))}
    print(json.dumps(result, indent=2))  # noqa: T201
    return result


if __name__ == "__main__":
    main()
