"""Specimen motion along x: eta(t) and the linear interpolation in eta (paper sections 2.1 and 5.2).

The paper's runs use eta(t) = 3 L_h sin(2 pi t / Pi) with Pi = 0.15 t_E; the amplitude and
period come from :class:`twin.scenario.OscillationSpec`.  A disabled spec holds the
specimen at eta = 0.

Everything that depends on the position (the exchange factors F^s, hence P1 and P2 of
eq. 4) is tabulated at the positions eta_n and interpolated linearly in between, i.e.
with the hat functions hat_n(eta) of the table.  :func:`hat_interval` and
:func:`hat_weights` are that interpolation, used by the plant, the radiation model and
the averaging (eq. 11b).  A position outside the table (beyond a round-off tolerance) is
an error, never silently clamped: it means an amplitude the tables were not computed for.

For eta(t) = a sin(2 pi t / Pi) the period average of the hat functions (eq. 11b) has a closed
form: the time spent near eta has the arcsine density p(eta) = 1 / (pi sqrt(a^2 - eta^2)) on
(-a, a), independent of the period, so w_n = int hat_n(eta) p(eta) deta
(:func:`oscillation_weights`).

Example
-------
>>> from twin.scenario import OscillationSpec
>>> eta = eta_function(OscillationSpec(enabled=True, amplitude=0.048, period=18.0))
>>> round(eta(4.5), 6)
0.048
>>> hat_weights([-0.05, 0.0, 0.05], 0.0125).tolist()
[0.0, 0.75, 0.25]
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Callable, Sequence

import numpy as np
from numpy.typing import ArrayLike, NDArray

from twin.scenario import OscillationSpec

Array = NDArray[np.float64]

#: positions within this fraction of the table's span beyond its ends count as the end node (round-off)
TABLE_TOLERANCE = 1e-9


def eta_function(spec: OscillationSpec, t0: float = 0.0) -> Callable[[float], float]:
    """eta(t) in m: ``amplitude sin(2 pi (t - t0) / period)`` if enabled, else 0.

    Parameters
    ----------
    spec : amplitude (m) and period (s)
    t0 : s, time at which the motion starts from eta = 0 upwards (for switching mid-run)
    """
    if not spec.enabled or spec.amplitude == 0.0:
        return lambda t: 0.0
    a, omega = float(spec.amplitude), 2.0 * math.pi / float(spec.period)
    return lambda t: a * math.sin(omega * (t - t0))


def hat_interval(nodes: Sequence[float], eta: float) -> tuple[int, float]:
    """Interval k and weight w with f(eta) = (1 - w) f_k + w f_{k+1} (linear interpolation on ``nodes``).

    ``nodes`` are increasing positions (m), a Python sequence (this runs once per plant
    right-hand side: pure Python on purpose, numpy's scalar overhead would dominate).  A
    one-node table is position independent: (0, 0.0) for any eta.

    Raises
    ------
    ValueError
        If eta lies outside [nodes[0], nodes[-1]] by more than ``TABLE_TOLERANCE`` of the span.
    """
    m = len(nodes)
    if m == 1:
        return 0, 0.0
    lo, hi = nodes[0], nodes[-1]
    tol = TABLE_TOLERANCE * max(1.0, hi - lo)
    if not lo - tol <= eta <= hi + tol:
        raise ValueError(f"eta = {eta:.6g} m lies outside the exchange-factor table [{lo:g}, {hi:g}] m")
    k = min(max(bisect.bisect_right(nodes, eta) - 1, 0), m - 2)
    w = (eta - nodes[k]) / (nodes[k + 1] - nodes[k])
    return k, min(max(w, 0.0), 1.0)


def hat_weights(nodes: ArrayLike, eta: float) -> Array:
    """The hat-function weights hat_n(eta), shape (n_eta,): non-negative, summing to 1.

    Same interval and errors as :func:`hat_interval`.
    """
    nv = [float(v) for v in np.atleast_1d(np.asarray(nodes, float))]
    k, w = hat_interval(nv, float(eta))
    out = np.zeros(len(nv))
    out[k] += 1.0 - w
    if w > 0.0:
        out[k + 1] += w
    return out


def _arcsine_moments(a: float, lo: float, hi: float) -> tuple[float, float]:
    """int_lo^hi p(eta) deta and int_lo^hi eta p(eta) deta for the arcsine density on (-a, a)."""
    lo, hi = max(lo, -a), min(hi, a)
    if hi <= lo:
        return 0.0, 0.0
    m0 = (np.arcsin(hi / a) - np.arcsin(lo / a)) / np.pi
    m1 = (np.sqrt(max(a * a - lo * lo, 0.0)) - np.sqrt(max(a * a - hi * hi, 0.0))) / np.pi
    return float(m0), float(m1)


def oscillation_weights(eta_nodes: Array, amplitude: float) -> Array:
    """Exact period-average weights w_n of the hat functions for eta = a sin(2 pi t / Pi).

    Parameters
    ----------
    eta_nodes : (n_eta,) increasing positions of the exchange-factor table, m
    amplitude : a in m, at most max(|eta_nodes|)

    Returns
    -------
    (n_eta,) weights, non-negative, summing to 1 (eq. 11b with P linear in hat_n).
    """
    nodes = np.asarray(eta_nodes, float)
    a = float(amplitude)
    if a <= 0.0 or len(nodes) == 1:
        return hat_weights(nodes, 0.0)
    if a > min(-nodes[0], nodes[-1]) + 1e-12:
        raise ValueError(f"oscillation amplitude {a} m exceeds the exchange-factor table [{nodes[0]}, {nodes[-1]}] m")
    w = np.zeros(len(nodes))
    for n in range(len(nodes)):
        if n > 0:  # rising flank (eta - eta_{n-1}) / d on [eta_{n-1}, eta_n]
            lo, hi = nodes[n - 1], nodes[n]
            m0, m1 = _arcsine_moments(a, lo, hi)
            w[n] += (m1 - lo * m0) / (hi - lo)
        if n < len(nodes) - 1:  # falling flank (eta_{n+1} - eta) / d on [eta_n, eta_{n+1}]
            lo, hi = nodes[n], nodes[n + 1]
            m0, m1 = _arcsine_moments(a, lo, hi)
            w[n] += (hi * m0 - m1) / (hi - lo)
    return w


def average_weights(eta_nodes: Array, oscillation: OscillationSpec | None) -> Array:
    """Weights for the time-averaged model (11): oscillating if enabled, else eta = 0."""
    if oscillation is None or not oscillation.enabled:
        return hat_weights(eta_nodes, 0.0)
    return oscillation_weights(eta_nodes, oscillation.amplitude)
