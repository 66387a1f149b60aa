"""Time averaging of the radiation source over one oscillation period (paper eq. 11b).

chi(theta, u, eta) depends on eta only through P1(eta) and P2(eta) (eq. 4), which are
interpolated linearly between the precomputed positions eta_n (section 2.1), i.e.
P(eta) = sum_n hat_n(eta) P_n.  Hence, exactly,

    chi_av = (1/Pi) int_t^{t+Pi} chi(theta, u, eta(t')) dt' = chi evaluated with P_av,
    P_av = sum_n w_n P_n,   w_n = (1/Pi) int_0^Pi hat_n(eta(t)) dt.

For eta(t) = a sin(2 pi t / Pi) the time spent near eta has the arcsine density
p(eta) = 1 / (pi sqrt(a^2 - eta^2)) on (-a, a), independent of the period, so

    w_n = int hat_n(eta) p(eta) deta

in closed form with int p = asin(eta / a) / pi and int eta p = -sqrt(a^2 - eta^2) / pi.
The fixed specimen (no oscillation or a = 0) is the special case w = hat(0).

Example
-------
>>> import numpy as np
>>> w = oscillation_weights(np.linspace(-0.05, 0.05, 5), 0.05)
>>> round(float(w.sum()), 12)
1.0
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from twin.scenario import OscillationSpec

Array = NDArray[np.float64]


class RadiationTables(Protocol):
    """What the averaging needs from :class:`twin.radiation.RadiationModel`."""

    eta_nodes: Array
    P1: Array
    P2: Array


def _arcsine_moments(a: float, lo: float, hi: float) -> tuple[float, float]:
    """int_lo^hi p(eta) deta and int_lo^hi eta p(eta) deta for the arcsine density on (-a, a)."""
    lo, hi = max(lo, -a), min(hi, a)
    if hi <= lo:
        return 0.0, 0.0
    m0 = (np.arcsin(hi / a) - np.arcsin(lo / a)) / np.pi
    m1 = (np.sqrt(max(a * a - lo * lo, 0.0)) - np.sqrt(max(a * a - hi * hi, 0.0))) / np.pi
    return float(m0), float(m1)


def static_weights(eta_nodes: Array, eta: float) -> Array:
    """Linear-interpolation weights hat_n(eta), shape (n_eta,) (fixed specimen position)."""
    nodes = np.asarray(eta_nodes, float)
    if len(nodes) == 1:
        return np.ones(1)
    if not nodes[0] - 1e-12 <= eta <= nodes[-1] + 1e-12:
        raise ValueError(f"eta = {eta} m lies outside the exchange-factor table [{nodes[0]}, {nodes[-1]}] m")
    eye = np.eye(len(nodes))
    return np.array([np.interp(eta, nodes, eye[n]) for n in range(len(nodes))])


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
        return static_weights(nodes, 0.0)
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
        return static_weights(eta_nodes, 0.0)
    return oscillation_weights(eta_nodes, oscillation.amplitude)


def averaged_matrices(radiation: RadiationTables, oscillation: OscillationSpec | None) -> tuple[Array, Array]:
    """P1_av (N_s, N_s + N_w) and P2_av (N_s, N_lamps) of eq. (11b), in the units of P1, P2."""
    w = average_weights(radiation.eta_nodes, oscillation)
    P1 = np.tensordot(w, np.asarray(radiation.P1), axes=1)
    P2 = np.tensordot(w, np.asarray(radiation.P2), axes=1)
    return P1, P2
