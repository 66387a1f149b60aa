"""EKF (paper section 3.2) on the full-order plant with noisy TCs and faulty sensors.

One open-loop plant run (fixed specimen, cold start, constant powers that hold the fillet mean
at 1100 K, 2 t_E = 240 s) feeds two estimators started 50 K off: one with the clean readings of
TC1-3, one with injected faults (a TC dropping out, a TC jumping by 300 K, an absurd spike).
Validation is the paper's: the estimate at TC4 against the TC4 reading, for the three TC4
positions of section 3.1 at once (TC4 is not used by the EKF, so one run serves all three).
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.estimation.ekf import Estimator
from twin.furnace.simulated.plant import Plant
from twin.furnace.simulated.thermocouples import Thermocouples
from twin.model.discrete import discrete_model

CFG = small_config()
SETPOINT = 1100.0  # K
T_E = 120.0  # s, furnace.md
TC4_POSITIONS = [(0.375, 0.5), (0.5, 0.5), (0.625, 0.5)]  # relative, paper section 3.1
INITIAL_OFFSET = 50.0  # K, estimate starts this far above the true 300 K plate


def _faulty(y: np.ndarray, t: float) -> np.ndarray:
    y = y.copy()
    if 40.0 <= t < 60.0:
        y[1] = np.nan  # TC2 drops out for 20 s
    if 80.0 <= t < 90.0:
        y[2] += 300.0  # TC3 jumps by 300 K for 10 s (loose contact)
    if abs(t - 100.0) < 1e-9:
        y[0] = 5000.0  # one absurd TC1 sample
    return y


@pytest.fixture(scope="module")
def run(small_radiation):
    model = discrete_model(CFG, small_radiation, None)
    u = model.hold_powers(SETPOINT)
    plant = Plant(CFG, small_radiation)
    s = CFG.specimen
    positions = CFG.tc_positions()[:3] + [(x * s.length, y * s.width) for x, y in TC4_POSITIONS]
    tcs = Thermocouples(CFG, positions)
    phi4 = model.fe.phi(np.asarray(positions[3:]))
    rng = np.random.default_rng(20180611)
    state = plant.start(np.full(plant.n, s.initial_temperature))
    theta0 = s.initial_temperature + INITIAL_OFFSET
    clean, faulty = Estimator(model, CFG, theta0), Estimator(model, CFG, theta0)
    # the paper's EKF to the letter: Jacobian (16) at every sample, covariance (15) in float64
    exact_cfg = CFG.with_overrides({"ekf.jacobian_tolerance": 0.0, "ekf.covariance_precision": "double"})
    exact = Estimator(model, exact_cfg, theta0)
    t_s = CFG.sampling.t_s
    out: dict[str, list] = {k: [] for k in ("t", "tc4_err", "tc4_err_faulty", "used", "used_faulty", "min_eig",
                                            "gap", "exact_gap", "exact_P_gap")}
    for j in range(int(round(2 * T_E / t_s))):
        t = j * t_s
        y = tcs.read(state.T, rng, CFG.sensors.noise)
        a = clean.update(y[:3])
        b = faulty.update(_faulty(y[:3], t))
        c = exact.update(y[:3])
        out["exact_gap"].append(np.max(np.abs(a.theta - c.theta)))
        out["exact_P_gap"].append(np.max(np.abs(a.P - c.P)) / np.max(np.abs(c.P)))
        out["t"].append(t)
        out["tc4_err"].append(phi4 @ a.theta - y[3:])
        out["tc4_err_faulty"].append(phi4 @ b.theta - y[3:])
        out["used"].append(clean.last_info.used.copy())
        out["used_faulty"].append(faulty.last_info.used.copy())
        out["gap"].append(np.max(np.abs(a.theta - b.theta)))
        if j % 100 == 0:
            out["min_eig"].append(np.linalg.eigvalsh(b.P).min())
            assert np.array_equal(b.P, b.P.T)
        state = plant.advance(state, u, t_s, lambda _t: 0.0)
        clean.predict(u)
        faulty.predict(u)
        exact.predict(u)
    return {k: np.asarray(v) for k, v in out.items()}


@pytest.mark.slow
def test_tc4_error_after_a_quarter_of_t_e(run) -> None:
    after = run["t"] >= T_E / 4
    err = np.abs(run["tc4_err"][after]).max(axis=0) / SETPOINT
    # brief: below 1.5 % of the setpoint after t_E / 4 at every TC4 position (measured 0.77 / 0.89 / 1.05 %)
    assert (err < 0.015).all(), err
    assert run["used"].all()  # clean readings are never gated (6 sigma gate vs model mismatch)
    # the initial 50 K offset really was there and was corrected
    assert np.abs(run["tc4_err"][0]).min() > 0.8 * INITIAL_OFFSET


@pytest.mark.slow
def test_faulty_readings_do_not_derail_the_estimate(run) -> None:
    t, used = run["t"], run["used_faulty"]
    assert not used[(t >= 40) & (t < 60), 1].any()  # dropped TC2 never used
    assert not used[(t >= 80) & (t < 90), 2].any()  # 300 K jump gated throughout
    assert not used[np.isclose(t, 100.0), 0].any()  # the 5000 K spike gated
    assert used[(t >= 120)].all()  # after the faults every TC is used again
    # while TC2 is out in the fastest part of the heat-up the centre is less observable: the TC4 error
    # grows (measured 1.61 % at 0.5 L_s vs 0.89 % clean); 2.5 % allows for that, while letting the
    # 300 K jump or the 5000 K spike through would put the estimate tens to hundreds of K off
    after = t >= T_E / 4
    err = np.abs(run["tc4_err_faulty"][after]).max(axis=0) / SETPOINT
    assert (err < 0.025).all(), err
    # after the faults the estimate rejoins the clean one (measured: 1e-3 K after 150 s, 1e-6 K at the end)
    assert run["gap"][t >= 150].max() < 0.5
    assert run["gap"][-1] < 0.05
    # P stays symmetric positive definite (Joseph form), checked every 10 s
    assert run["min_eig"].min() > 0


@pytest.mark.slow
def test_cached_jacobian_and_single_precision_covariance_match_the_exact_filter(run) -> None:
    """The default estimator (Phi re-evaluated after 2 K, Phi P Phi^T in float32) vs the paper's EKF.

    Measured on this run (and with /tmp-style variants while choosing the defaults): the 2 K
    Jacobian tolerance alone moves P by up to 5e-3 of its largest entry and the estimate by 4 mK;
    single precision alone by 1.3e-4 and 1.2 mK; together 5.5e-3 and 5 mK.  The bounds leave a
    factor 4-10 and stay 20 times below the 1 K TC noise, the scale the filter works at.
    """
    assert run["exact_P_gap"].max() < 2e-2, run["exact_P_gap"].max()
    assert run["exact_gap"].max() < 0.05, run["exact_gap"].max()
