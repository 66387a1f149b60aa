"""The model-error measurement of ``[ekf.model_error]`` (twin.experiments.model_error_stats, issue 25)."""

from __future__ import annotations

import numpy as np
import pytest

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


def test_coverage_by_scale_counts_each_run_and_the_pool() -> None:
    """Two hand-made runs (t_E = 1 s, fields on a 4 x 4 grid, sigma = 1 K): the first's steady error is 0.5 K in
    every cell (covered at any k >= 0.25), the second's +3 K in half its fillet cells and -1 K in the rest (at
    k = 1: half covered; at k = 1.5: all).  Transient errors of 10 K are left out of the steady figures."""
    from twin.experiments.model_error_stats import coverage_by_scale
    from twin.physics.fillet import Fillet

    x = (np.arange(4) + 0.5) * 0.1
    y = (np.arange(4) + 0.5) * 0.05
    mask = Fillet.on_grid(x, y, 0.4, 0.2).mask
    t = np.linspace(0.0, 2.0, 21)
    steady = (t >= 1.5) & (t <= 2.0)

    def run(steady_err: np.ndarray) -> dict:
        err = np.full((21, 4, 4), 10.0)
        err[steady] = steady_err
        true = np.full((21, 4, 4), 1000.0)
        return dict(x=x, y=y, L_s=0.4, W_s=0.2, t_field=t, t_E=1.0, field_true=true, field_hat=true + err,
                    field_sigma=np.ones((21, 4, 4)))

    second = np.where(np.arange(16).reshape(4, 4) % 2 == 0, 3.0, -1.0)
    share = float(np.mean(second[mask] == -1.0))  # the fillet cells at -1 K
    out = coverage_by_scale([run(np.full((4, 4), 0.5)), run(second)], [1.0, 1.5])
    k1, k15 = out["rows"]
    assert k1["steady"] == [1.0, share] and k15["steady"] == [1.0, 1.0]
    assert k1["pooled"] == 0.5 * (1.0 + share) and k1["in_band"] == 0 and k15["in_band"] == 0
    assert k1["transient_min"] == 0.0  # 10 K against 2 K: nothing covered
    assert out["run_mean"][0] == 0.5
    assert out["run_mean"][1] == float(np.mean(second[mask]))
    assert out["within_sd"][0] == 0.0 and out["within_sd"][1] == float(np.std(second[mask]))
    m, w = np.array(out["run_mean"]), np.array(out["within_sd"])
    assert out["rho"] == float(np.sqrt(np.mean(m**2) / (np.mean(m**2) + np.mean(w**2))))


def test_the_share_of_runs_in_band_under_an_exact_sigma() -> None:
    """Oracles: rho = 0 is white noise, every run at 95.4 % (in 90-99 %); rho -> 1 is one offset per run, each run
    covered fully or not at all (none in band); in between, a Monte Carlo of the same two-part error."""
    from twin.experiments.model_error_stats import in_band_share

    assert in_band_share(0.0) == 1.0
    assert in_band_share(0.999) < 0.02
    rng = np.random.default_rng(5)
    rho, runs, cells = 0.75, 3000, 5000
    a = rng.normal(0.0, rho, runs)
    e = a[:, None] + rng.normal(0.0, np.sqrt(1 - rho**2), (runs, cells))
    cover = np.mean(np.abs(e) <= 2.0, axis=1)
    mc = float(np.mean((cover >= 0.90) & (cover <= 0.99)))
    assert in_band_share(rho) == pytest.approx(mc, abs=0.03)  # 5000 cells per run: coverage to +-0.003
