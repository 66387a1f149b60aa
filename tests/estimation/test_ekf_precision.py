"""The covariance prediction's precision (twin.estimation.ekf.propagate_covariance, eq. 15).

Oracle: the products written out in numpy in the stated precision: a float32 Phi forms Phi P Phi^T in float32
(``ekf.covariance_precision = "single"``: half the cost of the two n x n x n products), a float64 Phi in
float64; the result is float64, symmetric, with Q added.  A precision slip (the float32 Phi multiplied with the
float64 P, silently upcast) gives other numbers and the single-precision setting no saving.
"""

from __future__ import annotations

import numpy as np

from twin.estimation.ekf import propagate_covariance


def _case(n: int = 40, seed: int = 0):
    rng = np.random.default_rng(seed)
    Phi = np.eye(n) * 0.97 + 0.01 * rng.standard_normal((n, n))
    L = rng.standard_normal((n, n))
    P = L @ L.T / n + np.eye(n)
    Q = np.diag(rng.uniform(0.01, 0.1, n))
    return Phi, P, Q


def test_a_single_precision_phi_forms_the_product_in_single_precision() -> None:
    Phi, P, Q = _case()
    out = propagate_covariance(Phi.astype(np.float32), P, Q)
    f32 = Phi.astype(np.float32)
    expected = (f32 @ P.astype(np.float32) @ f32.T).astype(np.float64) + Q
    expected = 0.5 * (expected + expected.T)
    assert out.dtype == np.float64
    np.testing.assert_array_equal(out, expected)
    upcast = f32 @ P @ f32.T + Q  # float32 Phi with the float64 P: numpy computes in float64
    assert not np.array_equal(out, 0.5 * (upcast + upcast.T))


def test_a_double_precision_phi_forms_it_in_double() -> None:
    Phi, P, Q = _case(seed=1)
    out = propagate_covariance(Phi, P, Q)
    expected = Phi @ P @ Phi.T + Q
    np.testing.assert_array_equal(out, 0.5 * (expected + expected.T))
    np.testing.assert_array_equal(out, out.T)
