"""Net-radiation matrices of the furnace chamber, paper eqs. (4)-(5).

For grey surfaces with diffuse emission, specular + diffuse reflection and the
specular exchange factors F^s (arriving fractions), the irradiation is H = F^s J and
the diffuse radiosity J = eps sigma T^4 + rho^d H.  The net flux leaving surface i is
q_i = eps_i (sigma T_i^4 - H_i), i.e. (eq. 5)

    q = diag(eps) (I - F^s diag(rho^d))^-1 (I - F^s + F^s diag(rho^s)) sigma T^4 = P T^4.

Surfaces are ordered [specimen (front, back); walls; lamps].  The lamps have a known
net flux u instead of a known temperature; eliminating T_lamp^4 from the lamp rows
gives eq. (4): P1 = P11 - P12 P32^-1 P31, P2 = P12 P32^-1.  Finally the front and
back cell of each FD cell share the temperature T_k, so their rows are summed
(flux per unit plate area, both faces) and their columns merged.

Example
-------
>>> import numpy as np
>>> F = np.array([[0.0, 1.0], [1.0, 0.0]])  # two infinite parallel plates
>>> P = net_radiation_matrix(F, np.array([0.5, 0.5]), np.zeros(2), np.array([0.5, 0.5]))
>>> q = P @ np.array([1000.0**4, 0.0])
>>> bool(np.isclose(q[0], 5.670374419e-8 * 1e12 / (1 / 0.5 + 1 / 0.5 - 1)))
True
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from twin.config import STEFAN_BOLTZMANN

Array = NDArray[np.float64]


def net_radiation_matrix(F: Array, emissivity: Array, specular: Array, diffuse: Array) -> Array:
    """P of eq. (5) in W/(m^2 K^4): net flux leaving each surface per unit area = P @ T^4."""
    n = len(emissivity)
    eye = np.eye(n)
    lhs = eye - F * diffuse[None, :]
    rhs = eye - F + F * specular[None, :]
    return STEFAN_BOLTZMANN * emissivity[:, None] * np.linalg.solve(lhs, rhs)


def specimen_matrices(P: Array, n_specimen: int, n_walls: int, lamp_flux_scale: Array) -> tuple[Array, Array]:
    """P1 (N_s, N_s + N_w) and P2 (N_s, N_lamps) of eq. (4) from the full P of eq. (5).

    Parameters
    ----------
    P : (n, n) with n = 2 N_s + N_w + N_lamps, order [front; back; walls; lamps]
    n_specimen : N_s
    n_walls : N_w
    lamp_flux_scale : (N_lamps,) net flux density at the lamp's modelled surface per unit u
        (u refers to the area pi d l, the modelled cylinder has caps and facets)

    Returns
    -------
    P1 : W/(m^2 K^4), acting on [T^4; T_w^4]
    P2 : dimensionless, acting on u (W/m^2 at the lamp surface)
    """
    ns = n_specimen
    known = slice(0, 2 * ns + n_walls)
    lamps = slice(2 * ns + n_walls, P.shape[0])
    spec = slice(0, 2 * ns)
    P11, P12 = P[spec, known], P[spec, lamps]
    P31, P32 = P[lamps, known], P[lamps, lamps]
    X = np.linalg.solve(P32.T, P12.T).T  # P12 P32^-1
    P1_faces = P11 - X @ P31
    P2_faces = X * lamp_flux_scale[None, :]
    rows1 = P1_faces[:ns] + P1_faces[ns:]
    P1 = np.concatenate([rows1[:, :ns] + rows1[:, ns : 2 * ns], rows1[:, 2 * ns :]], axis=1)
    P2 = P2_faces[:ns] + P2_faces[ns:]
    return P1, P2
