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
The fixed specimen (no oscillation or a = 0) is the special case w = hat(0).  The weights are
:func:`twin.physics.motion.oscillation_weights`, shared with the plant-side steady states.

Example
-------
>>> import numpy as np
>>> from types import SimpleNamespace
>>> tables = SimpleNamespace(eta_nodes=np.linspace(-0.05, 0.05, 5), P1=np.arange(5.0)[:, None, None],
...                          P2=np.zeros((5, 1, 1)))
>>> P1_av, _ = averaged_matrices(tables, OscillationSpec(enabled=True, amplitude=0.05))
>>> round(float(P1_av[0, 0]), 12)    # symmetric motion about the middle node: the middle value
2.0
"""

from __future__ import annotations

from typing import Protocol

import numpy as np
from numpy.typing import NDArray

from twin.physics.motion import average_weights
from twin.scenario import OscillationSpec

Array = NDArray[np.float64]


class RadiationTables(Protocol):
    """What the averaging needs from :class:`twin.radiation.RadiationModel`."""

    eta_nodes: Array
    P1: Array
    P2: Array


def averaged_matrices(radiation: RadiationTables, oscillation: OscillationSpec | None) -> tuple[Array, Array]:
    """P1_av (N_s, N_s + N_w) and P2_av (N_s, N_lamps) of eq. (11b), in the units of P1, P2."""
    w = average_weights(radiation.eta_nodes, oscillation)
    P1 = np.tensordot(w, np.asarray(radiation.P1), axes=1)
    P2 = np.tensordot(w, np.asarray(radiation.P2), axes=1)
    return P1, P2
