"""Model-error statistics for the reported covariance (``[ekf.model_error]``, :mod:`twin.estimation.process_noise`).

From closed-loop runs against the honest truth (the simulated furnace is not the twin's model), per field
sample j with a field at j + 1 as well:

* the true field's best FE representation theta*_j = argmin ||M_theta theta - T_true,j|| (least squares on the
  FD cells) and what it leaves, r_j = T_true,j - M_theta theta*_j: ``representation_rms`` is the rms of r over
  the fillet's cells and the samples (the FE grid's share of the error, no filter can remove it);
* the one-step defect of the estimator's model (position-aware, nominal parameters) on that representation,
  d_j = theta*_{j+1} - F(theta*_j, u_j; eta_j) (eqs. 12a, 14): the process noise the model really has;
  its second moment D = mean d d^T (bias included: a systematic error is noise to the filter);
* q0, q1 of Q = q0 (q1 sign(M) + 1 1^T)^2 (the filter's form, section 3.2) fitted to D in the Frobenius norm
  (q0 in closed form for each q1 on a log grid).

:func:`replay_metrics` re-runs a run's estimator on its stored readings, inputs and positions with another
configuration's reported covariance (the estimate itself does not depend on it) and gives the run's metrics with
that ``field_sigma``/``nis``: how a scale of q0 is tuned and checked without re-running the furnace.

Example
-------
>>> import numpy as np
>>> S = np.sign(np.array([[2.0, 1.0, 0.0], [1.0, 2.0, 1.0], [0.0, 1.0, 2.0]]))
>>> q0, q1 = fit_form(0.3 * np.linalg.matrix_power(0.7 * S + np.ones((3, 3)), 2), S)
>>> round(q0, 4), round(q1, 2)
(0.3, 0.7)
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.physics.fillet import Fillet
from twin.scenario import Scenario

Array = NDArray[np.float64]


def fit_form(D: Array, S: Array) -> tuple[float, float]:
    """(q0, q1) minimising ||D - q0 (q1 S + 1 1^T)^2||_F (S = sign(M)); q1 on a log grid refined twice."""
    n = D.shape[0]
    J = np.ones((n, n))

    def best(q1: float) -> tuple[float, float]:
        B = np.linalg.matrix_power(q1 * S + J, 2)
        q0 = max(float(np.sum(D * B) / np.sum(B * B)), 1e-30)
        return float(np.linalg.norm(D - q0 * B)), q0

    grid = np.concatenate([[0.0], np.logspace(-3, 3, 61)])
    for _ in range(3):
        scores = [best(q)[0] for q in grid]
        i = int(np.argmin(scores))
        lo, hi = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
        grid = np.linspace(lo, hi, 41)
    q1 = float(grid[int(np.argmin([best(q)[0] for q in grid]))])
    return best(q1)[1], q1


def defects(cfg: FurnaceConfig, ts: Mapping[str, Any], model: Any) -> tuple[Array, Array]:
    """One-step defects d_j (m, n) K and representation residuals over the fillet (m', cells) K of one run
    (``timeseries.npz`` layout with ``field_true``); ``model`` the estimator's (``step(theta, u, eta)``)."""
    fe = model.fe
    Mt = np.asarray(fe.M_theta, float)
    pinv = np.linalg.pinv(Mt)
    t, u, eta = np.asarray(ts["t"], float), np.asarray(ts["u"], float), np.asarray(ts["eta"], float)
    tf = np.asarray(ts["t_field"], float)
    truth = np.asarray(ts["field_true"], float).reshape(len(tf), -1)
    theta = truth @ pinv.T  # (m, n) least-squares node values
    resid = truth - theta @ Mt.T
    fillet = Fillet.on_grid(np.asarray(ts["x"]), np.asarray(ts["y"]), float(ts["L_s"]), float(ts["W_s"]))
    t_s = cfg.sampling.t_s
    out = []
    for j in range(len(tf) - 1):
        if abs(tf[j + 1] - tf[j] - t_s) > 1e-6:
            continue
        i = int(np.searchsorted(t, tf[j] - 1e-9))
        out.append(theta[j + 1] - model.step(theta[j], u[i], float(eta[i])))
    return np.asarray(out), resid[:, fillet.mask.ravel()]


def model_error_statistics(cfg: FurnaceConfig, runs: Sequence[Mapping[str, Any]], model_for: Any) -> dict[str, Any]:
    """``{"q0", "q1", "representation_rms", "samples", "defect_rms"}`` from runs (module docstring);
    ``model_for(ts)`` gives the estimator's model of a run (its oscillation)."""
    ds, rs = [], []
    for ts in runs:
        d, r = defects(cfg, ts, model_for(ts))
        ds.append(d)
        rs.append(r.ravel())
    d_all = np.concatenate(ds)
    D = d_all.T @ d_all / len(d_all)
    fe = model_for(runs[0]).fe
    q0, q1 = fit_form(D, np.sign(np.asarray(fe.M, float)))
    return {"q0": q0, "q1": q1, "representation_rms": float(np.sqrt(np.mean(np.concatenate(rs) ** 2))),
            "samples": len(d_all), "defect_rms": float(np.sqrt(np.mean(d_all**2)))}


def bias_statistics(cfg: FurnaceConfig, runs: Sequence[Mapping[str, Any]], model_for: Any, degree: int,
                    temperature: float = 1000.0, exponent: float | None = None) -> dict[str, Any]:
    """The model's constant bias (``[ekf.model_error] bias_*``, :mod:`twin.estimation.model_bias`): each run's
    mean one-step defect over its steady window (1.5 t_E <= t <= 2 t_E, where the run's forcing error has
    settled and the noise averages out) fitted by the Legendre shape of ``degree`` at the nodes (least squares).
    The bias grows with the temperature: each run's mean is divided by (T_r / ``temperature``)^p, T_r the mean of
    the truth's best node values over the window, p = ``exponent`` or, None, fitted to the runs (log of the mean's
    rms against log T_r; 0 with a single temperature).  Returns
    ``{"bias_variance": mean over the runs of each coefficient squared, "coefficients": per run,
    "bias_node_variance": mean square of what the shape leaves of the runs' means (each node's own constant
    forcing), "bias_temperature", "bias_exponent", "mean_rms": rms of the runs' mean defects (not scaled),
    "q0_white", "q1_white": the form of Q fitted to the steady window's defects less their run's mean (what is
    left of the defect once the bias is carried)}`` (K per sample, at ``temperature``)."""
    from twin.estimation.model_bias import node_shape

    means, temps, centred = [], [], []
    for ts in runs:
        model = model_for(ts)
        d, _ = defects(cfg, ts, model)
        tf = np.asarray(ts["t_field"], float)
        t_E = float(ts["t_E"])
        # the sample time of each defect (defects keeps the j with a field one step later)
        t_j = tf[:-1][np.abs(np.diff(tf) - cfg.sampling.t_s) <= 1e-6]
        steady = d[(t_j >= 1.5 * t_E - 1e-9) & (t_j <= 2.0 * t_E + 1e-9)]
        mean = steady.mean(axis=0)
        centred.append(steady - mean)
        means.append(mean)
        window = (tf >= 1.5 * t_E - 1e-9) & (tf <= 2.0 * t_E + 1e-9)
        truth = np.asarray(ts["field_true"], float)[window].reshape(int(window.sum()), -1)
        temps.append(float(np.mean(truth @ np.linalg.pinv(np.asarray(model.fe.M_theta, float)).T)))
    T = np.asarray(temps)
    rms = np.sqrt(np.mean(np.square(means), axis=1))
    if exponent is None:
        exponent = float(np.polyfit(np.log(T), np.log(rms), 1)[0]) if np.ptp(T) > 1.0 else 0.0
    G = node_shape(model.fe, degree)
    scaled = np.asarray(means) / ((T / temperature) ** exponent)[:, None]
    C = np.linalg.lstsq(G, scaled.T, rcond=None)[0].T
    resid = scaled - C @ G.T
    w = np.concatenate(centred)
    q0_white, q1_white = fit_form(w.T @ w / len(w), np.sign(np.asarray(model.fe.M, float)))
    return {"bias_variance": [float(v) for v in np.mean(C**2, axis=0)], "coefficients": C.tolist(),
            "bias_node_variance": float(np.mean(np.square(resid))), "bias_temperature": float(temperature),
            "bias_exponent": float(exponent), "mean_rms": float(np.sqrt(np.mean(np.square(means)))),
            "q0_white": q0_white, "q1_white": q1_white}


def replay_metrics(cfg: FurnaceConfig, ts: Mapping[str, Any], tables: Any) -> tuple[dict[str, Any], float]:
    """(metrics, largest |replayed - stored estimate| in K over the stored fields) of a stored run whose estimator
    is replayed with ``cfg`` (its ``[ekf.model_error]``); ``tables`` the twin's model tables of the furnace.
    Follows the loop's order (update with TC1-3, learning while the reference holds, then predict with the applied
    powers at eta); a run whose fault detection left a TC out or that changed its reference live is not replayed
    exactly (the deviation says so)."""
    metrics, deviation = replay_variants(cfg, ts, tables, [cfg.ekf.model_error])
    return metrics[0], deviation


class _Reports:
    """Several reported covariances fed by one filter (the ``reported`` of the estimator): the first answers."""

    def __init__(self, members: list[Any]) -> None:
        self.members = members

    @property
    def P(self) -> Any:
        return self.members[0].P

    @property
    def nis(self) -> float:
        return float(self.members[0].nis)

    def predict(self, Phi: Any, temperature: float | None = None) -> None:
        for r in self.members:  # each with its own bias growth
            r.predict(Phi, temperature)

    def update(self, *args: Any) -> None:
        for r in self.members:
            r.update(*args)


def replay_variants(cfg: FurnaceConfig, ts: Mapping[str, Any], tables: Any, model_errors: list[Any],
                    ) -> tuple[list[dict[str, Any]], float]:
    """:func:`replay_metrics` for several ``[ekf.model_error]`` at once (one filter, one reported covariance per
    entry, :class:`twin.config.ModelError` or a dict of its fields): the metrics of each and the deviation."""
    from twin.estimation.choice import build_estimator
    from twin.estimation.uncertainty import FieldUncertainty
    from twin.runs.metrics import compute_metrics

    if any(me is None for me in model_errors):
        raise ValueError("a replay compares reported covariances: each variant needs an [ekf.model_error]")
    variants = [cfg.with_overrides({"ekf.model_error": me if isinstance(me, dict) else me.model_dump()})
                for me in model_errors]
    sc = Scenario.model_validate_json(str(ts["scenario"]))
    t, tc, u, eta = (np.asarray(ts[k], float) for k in ("t", "tc", "u", "eta"))
    y0 = float(np.nanmean(tc[0, :3]))
    ests = [build_estimator(sc.estimator, tables, sc.oscillation, v, y0) for v in variants]
    est = ests[0]
    reports = _Reports([e.reported for e in ests])
    est.reported = reports  # type: ignore[assignment]  # the first filter drives every reported covariance
    n = est.n
    mode_errors = [v.ekf.model_error.for_mode(sc.oscillation.enabled) for v in variants if v.ekf.model_error]
    uncs = [FieldUncertainty(est.model.fe, me.representation_rms) for me in mode_errors]
    tf = np.asarray(ts["t_field"], float)
    shape = np.asarray(ts["field_hat"]).shape
    sigmas = [np.zeros(shape) for _ in variants]
    nis = np.zeros((len(variants), len(t)))
    hat = np.zeros(shape)
    t_E, k = float(ts["t_E"]), 0
    for j in range(len(t)):
        est.update(tc[j, :3], learn=bool(t[j] >= t_E - 1e-9))
        nis[:, j] = [r.nis for r in reports.members]
        if k < len(tf) and abs(tf[k] - t[j]) < 1e-6:
            for s, unc, r in zip(sigmas, uncs, reports.members, strict=True):
                s[k] = unc.field_sigma(r.P[:n, :n])
            hat[k] = est.model.fe.field_on_cells(est.state.theta)
            k += 1
        est.predict(u[j], float(eta[j]))
    out = []
    for i in range(len(variants)):
        d = dict(ts)
        d.update(field_sigma=sigmas[i], nis=nis[i])
        out.append(compute_metrics(d))
    return out, float(np.max(np.abs(hat - np.asarray(ts["field_hat"], float))))


def coverage_by_scale(runs: Sequence[Mapping[str, Any]], scales: Sequence[float],
                      band: tuple[float, float] = (0.90, 0.99)) -> dict[str, Any]:
    """What a common factor k on the reported sigma does to each run's 2-sigma coverage of its steady window
    (issue 25's bar is 90-99 % there): per k, each run's coverage, the pooled one (all runs' fillet cells x
    samples together) and how many runs lie in ``band``; and the error's split into a part constant over each
    run's steady window (its mean over cells and samples, ``run_mean``) and the rest (``within_sd``).
    ``rho`` = sqrt(mean(run_mean^2) / (mean(run_mean^2) + mean(within_sd^2))): near 1 the error is one offset per
    run, and no sigma that does not know the run's offset can cover every run by 90-99 % (most are covered
    fully, those with a large offset hardly).  Uses each run's stored ``field_sigma``."""
    from twin.runs.metrics import window

    steady: list[tuple[Array, Array]] = []
    transient: list[tuple[Array, Array]] = []
    for ts in runs:
        fil = Fillet.on_grid(np.asarray(ts["x"]), np.asarray(ts["y"]), float(ts["L_s"]), float(ts["W_s"]))
        tf = np.asarray(ts["t_field"], float)
        err = (np.asarray(ts["field_hat"], float) - np.asarray(ts["field_true"], float))[..., fil.mask]
        sig = np.asarray(ts["field_sigma"], float)[..., fil.mask]
        w_st, w_tr = window(tf, float(ts["t_E"]), "steady"), window(tf, float(ts["t_E"]), "transient")
        steady.append((err[w_st], sig[w_st]))
        transient.append((err[w_tr], sig[w_tr]))
    means = np.array([float(e.mean()) for e, _ in steady])
    within = np.array([float(e.std()) for e, _ in steady])
    rho = float(np.sqrt(np.mean(means**2) / (np.mean(means**2) + np.mean(within**2))))
    n_cells = [e.size for e, _ in steady]
    rows = []
    for k in scales:
        cov = [float(np.mean(np.abs(e) <= 2.0 * k * s)) for e, s in steady]
        rows.append({"k": float(k), "steady": cov,
                     "pooled": float(np.dot(cov, n_cells) / np.sum(n_cells)),
                     "in_band": sum(band[0] <= c <= band[1] for c in cov),
                     "transient_min": min(float(np.mean(np.abs(e) <= 2.0 * k * s)) for e, s in transient)})
    return {"run_mean": means.tolist(), "within_sd": within.tolist(), "rho": rho, "rows": rows,
            "perfect_in_band": in_band_share(rho, band)}


def in_band_share(rho: float, band: tuple[float, float] = (0.90, 0.99)) -> float:
    """The share of runs whose 2-sigma coverage lies in ``band`` when sigma is *exact* for an error that is an
    offset a ~ N(0, rho^2 sigma^2) per run plus independent cell noise N(0, (1 - rho^2) sigma^2): a run with
    offset a is covered by C(a) = Phi((2 - a') / s) - Phi((-2 - a') / s), a' = a / sigma, s = sqrt(1 - rho^2).
    1 at rho = 0 (every run at 95.4 %), falling to 0 as rho -> 1 (each run covered fully or hardly)."""
    from scipy.stats import norm

    if rho <= 0.0:
        c = float(norm.cdf(2.0) - norm.cdf(-2.0))
        return float(band[0] <= c <= band[1])
    s = float(np.sqrt(max(1.0 - rho**2, 1e-12)))
    a = np.linspace(-8.0 * rho, 8.0 * rho, 160001)
    cover = norm.cdf((2.0 - a) / s) - norm.cdf((-2.0 - a) / s)
    density = norm.pdf(a / rho) / rho
    return float(np.sum(density * ((cover >= band[0]) & (cover <= band[1]))) * (a[1] - a[0]))
