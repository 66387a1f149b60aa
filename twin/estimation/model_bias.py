"""The shape of the model's constant bias in the reported covariance (issue 25, :mod:`twin.estimation.process_noise`).

On a fixed specimen the twin's model misses a forcing that stays the same for the run (measured: the mean of its
one-step defect over a run's steady window, :func:`twin.experiments.model_error_stats.bias_statistics`).  The
reported covariance carries it as a few constant coefficients c of a low-order shape over the specimen,
b(x, y) = sum_(a + e <= degree) c_ae P_a(xi) P_e(zeta) (Legendre polynomials, xi = 2 x / L_s - 1,
zeta = 2 y / W_s - 1), evaluated at the FE nodes: the columns of G.  Low order on purpose: a handful of
coefficients measured on a few tuning runs, not the run's own pattern.

Example
-------
>>> import numpy as np
>>> G = legendre_shape(np.array([0.0, 0.5, 1.0]), np.array([0.5, 0.5, 0.5]), 1)
>>> G.tolist()   # columns 1, P_1(zeta), P_1(xi)
[[1.0, 0.0, -1.0], [1.0, 0.0, 0.0], [1.0, 0.0, 1.0]]
>>> terms(2)
[(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (2, 0)]
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.polynomial import legendre
from numpy.typing import NDArray

Array = NDArray[np.float64]


def terms(degree: int) -> list[tuple[int, int]]:
    """The (a, e) of P_a(xi) P_e(zeta) with a + e <= degree, in the order of G's columns (none below 0)."""
    return [(a, e) for a in range(degree + 1) for e in range(degree + 1 - a)]


def legendre_shape(x_rel: Array, y_rel: Array, degree: int) -> Array:
    """G (len(x_rel), len(terms(degree))) at points given relative to the specimen (0..1 along L_s, W_s)."""
    xi, zeta = 2.0 * np.asarray(x_rel, float) - 1.0, 2.0 * np.asarray(y_rel, float) - 1.0
    cols = [legendre.legval(xi, [0.0] * a + [1.0]) * legendre.legval(zeta, [0.0] * e + [1.0])
            for a, e in terms(degree)]
    return np.column_stack(cols) if cols else np.zeros((len(xi), 0))


def node_shape(fe: Any, degree: int | None, extra_rows: int = 0, per_node: bool = False) -> Array:
    """G at the FE nodes of ``fe`` (:class:`twin.model.fe.FEModel`): the Legendre shape of ``degree`` (None: none),
    then with ``per_node`` one column per node (a constant forcing of each node on its own, the identity), and
    ``extra_rows`` zero rows appended (the calibrated parameters of a joint state: the bias forces temperatures
    only)."""
    nodes = fe.nodes()
    cols = [] if degree is None else [legendre_shape(nodes[:, 0] / fe.x_nodes[-1], nodes[:, 1] / fe.y_nodes[-1],
                                                     degree)]
    if per_node:
        cols.append(np.eye(len(nodes)))
    G = np.concatenate(cols, axis=1) if cols else np.zeros((len(nodes), 0))
    return np.concatenate([G, np.zeros((extra_rows, G.shape[1]))]) if extra_rows else G
