"""The model-error measurement of ``[ekf.model_error]`` (twin.experiments.model_error_stats, issue 25)."""

from __future__ import annotations

import numpy as np

from twin.config import small_config
from twin.estimation.choice import estimator_model
from twin.estimation.model_bias import node_shape
from twin.experiments.model_error_stats import bias_statistics
from twin.model.tables import model_tables
from twin.physics.grid import cell_centers
from twin.radiation import radiation_model
from twin.scenario import EstimatorChoice


def test_bias_statistics_recovers_a_planted_constant_forcing() -> None:
    """A truth that is the model itself plus a constant forcing G c (a degree-1 shape) and, in one run, a
    per-node part: the measured coefficient variances are the mean of c^2 over the runs, the per-node variance
    the mean square of what the shape leaves, and the white rest ~0.  Only the steady window (1.5..2 t_E)
    counts: a transient of another forcing before it is left out (a plausible bug: averaging the whole run)."""
    cfg = small_config()
    tables = model_tables(cfg, radiation_model(cfg))
    model = estimator_model(EstimatorChoice(calibrate=False), tables, None, cfg)
    fe = model.fe
    G = node_shape(fe, 1)
    x, y = cell_centers(cfg)
    t_s, t_E, m = cfg.sampling.t_s, 1.0, 22
    rng = np.random.default_rng(3)
    extra = 0.01 * rng.standard_normal(fe.n)
    extra -= G @ np.linalg.lstsq(G, extra, rcond=None)[0]  # orthogonal to the shape: the per-node part alone
    runs, cs = [], [np.array([-0.2, 0.01, 0.03]), np.array([-0.24, -0.01, 0.05])]
    u = np.full(len(cfg.lamps.groups), 0.5)
    for r, c in enumerate(cs):
        theta = np.full(fe.n, 900.0)
        fields = []
        for j in range(m):
            fields.append(np.asarray(fe.M_theta, float) @ theta)
            forcing = G @ c + (extra if r == 1 else 0.0)
            if j * t_s < t_E:  # the transient: another forcing, left out of the measurement
                forcing = forcing + 0.5
            theta = model.step(theta, u, 0.0) + forcing
        t = t_s * np.arange(m)
        runs.append({"t": t, "t_field": t, "u": np.tile(u, (m, 1)), "eta": np.zeros(m),
                     "field_true": np.asarray(fields).reshape(m, len(y), len(x)), "x": x, "y": y,
                     "L_s": cfg.specimen.length, "W_s": cfg.specimen.width, "t_E": t_E})
    b = bias_statistics(cfg, runs, lambda ts: model, 1, exponent=0.0)
    np.testing.assert_allclose(b["bias_variance"], np.mean(np.square(cs), axis=0), rtol=1e-4, atol=1e-9)
    assert np.isclose(b["bias_node_variance"], np.mean(extra**2) / 2, rtol=1e-3)  # one run of two has it
    assert b["q0_white"] < 1e-9
