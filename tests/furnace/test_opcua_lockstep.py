"""The OPC UA transport tested exactly (issue 23): ``furnace-twin emulate --lock-step`` in a subprocess, the twin
through its REST API, on the small furnace, with the DEFAULT estimator.

In lock step the emulator has no wall clock: it computes a sample when the twin's write for the previous one
has come, with that write's setpoints, and stamps it with its own time.  The run over OPC UA is then the
in-process run: the same readings reach the same estimator, the same commands the same plant.  What is left
to differ is the transport (a value scaled, rounded, reordered or lost, a sample filed under another time),
so the comparison asks for the in-process figures to 0.01 % of the setpoint; no timing enters, and a loaded
machine only makes the run slower.  (The real-time path has its own test with its own bounds:
``test_opcua_realtime.py``.)
"""

from __future__ import annotations

import numpy as np
import pytest
from opcua_helpers import run_over_opcua

from twin.config import small_config
from twin.runs.loop import ClosedLoop
from twin.scenario import Scenario

CFG = small_config()
# 700 K in t_E = 12 s, a 24 s run (steady window 18..24 s): the lamps heat near full power, then hold; the
# default estimator calibrates in the hold
LOCKSTEP = {"reference": {"setpoint": 700.0, "t_E": 12.0}, "duration": 24.0, "seed": 4, "tc_noise": 1.0}
#: 0.01 % of the setpoint (issue 23): what the transport may change.  Measured: 0 (bit for bit), so a transport
#: that rounds a reading to float32 (about 3e-5 K at 700 K, 5e-8 of the setpoint) would still pass it, one that
#: loses or misfiles a sample (a late-sample prediction moves the steady mean error by 0.02-0.3 %) would not.
EXACT = 1e-4


def _flat(metrics: dict, prefix: str = "") -> dict[str, float]:
    out: dict[str, float] = {}
    for k, v in metrics.items():
        if isinstance(v, dict):
            out.update(_flat(v, f"{prefix}{k}."))
        elif isinstance(v, int | float) and v is not None:
            out[f"{prefix}{k}"] = float(v)
    return out


@pytest.mark.slow
def test_lock_step_run_over_opcua_equals_the_in_process_run(tmp_path, small_radiation) -> None:
    in_process = ClosedLoop(CFG, Scenario.model_validate(LOCKSTEP), small_radiation)
    list(in_process.run())
    reference, ref = in_process.metrics(), in_process.timeseries()

    metrics, npz, stats = run_over_opcua(tmp_path, CFG, LOCKSTEP, "--lock-step", timeout=240)

    setpoint = LOCKSTEP["reference"]["setpoint"]
    print(f"steady mean error over OPC UA (lock step) {100 * metrics['mean_error_steady_max']:.4f} %, in process "
          f"{100 * reference['mean_error_steady_max']:.4f} %")  # shown with -rP
    assert len(npz["t"]) == len(ref["t"]) == 241 and metrics["late_samples"] == 0
    # the emulator computed sample k+1 with the twin's write for sample k (watchdog k + 1), every time (also after
    # the last sample: the loop applies u_240 before it ends)
    assert stats["applied"] == list(range(1, 242)), stats["applied"][:20]
    theirs, ours = _flat(metrics), _flat(reference)
    # what needs the simulated furnace's truth (true_*, the field error, the 2-sigma coverage and NEES of issue 25)
    # is not in a run over OPC UA
    compared = [k for k in ours if not k.startswith(("true_", "coverage_2sigma_", "nees_"))
                and k != "field_estimation_error_steady_max"]
    assert {"mean_error_steady_max", "tc4_error_steady_max", "calibration.lamp_efficiency.value"} <= set(compared)
    for key in compared:
        assert abs(theirs[key] - ours[key]) <= EXACT, (key, theirs[key], ours[key])
    for key in ("tc", "tc_hat", "T_mean_hat", "field_hat"):  # K
        assert np.nanmax(np.abs(npz[key] - ref[key])) <= EXACT * setpoint, key
    for key in ("u", "u_ff"):  # fractions of u_max
        assert np.max(np.abs(npz[key] - ref[key])) <= EXACT, key
    assert np.array_equal(np.isnan(npz["tc"]), np.isnan(ref["tc"]))
