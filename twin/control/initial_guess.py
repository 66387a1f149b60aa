"""Initial guesses of the feedforward OCP (section 4.1): mean tracking by a cheap knot-by-knot inversion.

IPOPT converges in a few tens of iterations only from a start that already tracks the fillet
mean: :func:`parametrized_guess` (distribution d and amplification v of eq. 18) and
:func:`free_guess` (free inputs, Remark 4) build one on the OCP's coarse grid (:class:`KnotGrid`).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from twin.control.plan import FeedforwardError, FeedforwardPlan
from twin.model.dynamics import DiscreteDynamics

Array = NDArray[np.float64]

#: Upper bound of v in the scaling eta^T d = 1 (mean eta = 1): every group with d_i >= 1/V_MAX can
#: saturate, and v = V_MAX is V_MAX times the mean heating power of all groups at full power.
V_MAX = 20.0
#: Smallest share (of the largest group) a warm-started distribution starts with.
WARM_FLOOR = 0.05


@dataclass(frozen=True)
class KnotGrid:
    """The OCP's coarse grid: K knot intervals of ``substeps`` samples t_s from t0."""

    t0: float
    t_s: float
    substeps: int  # samples per knot interval
    K: int  # knot intervals

    @property
    def N(self) -> int:
        return self.K * self.substeps

    @property
    def dt(self) -> float:
        return self.substeps * self.t_s

    @property
    def t_knots(self) -> Array:
        return np.asarray(self.t0 + self.dt * np.arange(self.K + 1), dtype=np.float64)

    @property
    def t_fine(self) -> Array:
        return np.asarray(self.t0 + self.t_s * np.arange(self.N + 1), dtype=np.float64)


def knot_weights(grid: KnotGrid) -> Array:
    """Trapezoidal weights over knots 1..K (knot 0 is fixed), normalized to the mean per sample."""
    w = np.full(grid.K, float(grid.substeps))
    w[-1] *= 0.5
    return w / grid.N


def tracking_amplification(model: DiscreteDynamics, dt: float, n_heun: int, T_knots: Array, th0: Array,
                            d: Array, width: float) -> Array:
    """v_k per interval such that u = smin(v_k d) brings c_m^T theta to T_ref at the next knot.

    A cheap inversion of the mean dynamics knot by knot (regula falsi on v in
    [0, V_MAX]; the mean after an interval grows monotonically with v), so the OCP
    starts from good mean tracking with the given distribution d.
    """
    from twin.control.shooting import heun_interval, smooth_min1

    K = len(T_knots) - 1
    v_out = np.empty(K)
    theta = np.asarray(th0, float)
    c = np.asarray(model.c_m, float)

    def mean_after(v: float) -> tuple[float, Array]:
        nxt = heun_interval(model, theta, smooth_min1(v * d, width)[0], dt, n_heun)
        return float(c @ nxt), nxt

    for k in range(K):
        target = T_knots[k + 1]
        a, (fa, xa) = 0.0, mean_after(0.0)
        b, (fb, xb) = V_MAX, mean_after(V_MAX)
        if target <= fa:
            v, theta = a, xa
        elif target >= fb:
            v, theta = b, xb
        else:
            v, x = a, xa
            for _ in range(12):  # Illinois regula falsi: superlinear, bracket kept
                v = b - (fb - target) * (b - a) / (fb - fa)
                fv, x = mean_after(v)
                if abs(fv - target) < 1e-3:
                    break
                if (fv - target) * (fb - target) < 0:
                    a, fa = b, fb
                else:
                    fa = target + 0.5 * (fa - target)
                b, fb = v, fv
            theta = x
        v_out[k] = v
    return v_out


def heating_efficiency(model: DiscreteDynamics, theta: Array) -> Array:
    """eta_i = c_m^T dF/du_i / t_s: fillet-mean heating rate (K/s) per unit fraction of group i,
    normalized to mean 1 over the working groups (eqs. 12a, 19).  Used to normalize the distribution:
    eta^T d = 1.  A failed group (its column of dF/du is zero: the model of a run whose fault detection
    took it as failed) gets eta_i = 0, and the OCP holds its d_i at 0."""
    B = np.asarray(model.jac_u(theta, np.full(model.m, 0.5)), float) / model.t_s
    eta = np.asarray(model.c_m, float) @ B
    dead = ~np.any(B != 0.0, axis=0)
    if dead.all():
        raise FeedforwardError("no lamp group heats the specimen", "model")
    if np.any(eta[~dead] <= 0):
        raise FeedforwardError("a lamp group does not heat the fillet (c_m^T B_i <= 0)", "model")
    eta[dead] = 0.0
    return np.asarray(eta / eta[~dead].mean(), float)


def parametrized_guess(model: DiscreteDynamics, grid: KnotGrid, n_heun: int, T_knots: Array, th0: Array,
                        warm: FeedforwardPlan | None, eta: Array, width: float) -> Array:
    """Initial (d, v) with eta^T d = 1.

    d: the previous plan's distribution u_c (or its mean free inputs) if given, else
    uniform inputs; v: the mean-tracking amplification for that d
    (:func:`tracking_amplification`).  Reusing the previous v(t) instead starts far
    off after a reference change (it tracks the old reference), and IPOPT then needed
    four times the iterations of a cold start.
    """
    if warm is not None and warm.u_c is not None:
        d = np.asarray(warm.u_c, float)
    elif warm is not None:
        d = warm.u_ff.mean(axis=0) / max(float(warm.u_ff.mean(axis=0).max()), 1e-9)
    else:
        d = np.ones(model.m)
    d = np.maximum(d, WARM_FLOOR)  # an interior start: IPOPT moves slowly off a bound
    d = d / float(eta @ d)
    v = tracking_amplification(model, grid.dt, n_heun, T_knots, th0, d, width)
    return np.concatenate([d, v])


def free_guess(model: DiscreteDynamics, grid: KnotGrid, n_heun: int, T_knots: Array, th0: Array,
                warm: FeedforwardPlan | None, width: float) -> Array:
    """Initial free inputs (K, m) row-major: the previous plan's inputs on the new intervals
    if given, else uniform mean-tracking inputs."""
    if warm is not None:
        t_mid = grid.t_knots[:-1] + 0.5 * grid.dt
        tw = warm.t[:-1]
        U = np.column_stack([np.interp(t_mid, tw, warm.u_ff[:, i]) for i in range(model.m)])
        return np.clip(U, 0.0, 1.0).ravel()
    ones = np.ones(model.m)
    v = tracking_amplification(model, grid.dt, n_heun, T_knots, th0, ones, width)
    from twin.control.shooting import smooth_min1

    return np.repeat(smooth_min1(v, width)[0][:, None], model.m, axis=1).ravel()
