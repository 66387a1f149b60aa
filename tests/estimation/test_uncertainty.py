"""The field's standard deviation (twin.estimation.uncertainty) against a Monte Carlo of the FE interpolation."""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.estimation.uncertainty import FieldUncertainty
from twin.model.fe import FEModel


@pytest.fixture(scope="module")
def fe() -> FEModel:
    return FEModel(small_config())


def _random_covariance(n: int, rng: np.random.Generator) -> np.ndarray:
    """A dense SPD covariance with strong correlations (K^2): common mode + random factors + a diagonal."""
    F = rng.normal(size=(n, 8))
    return 9.0 * np.ones((n, n)) + F @ F.T + np.diag(rng.uniform(0.5, 4.0, n))


def test_sigma_map_matches_monte_carlo_of_the_interpolation(fe: FEModel) -> None:
    """Oracle: draw theta ~ N(0, P), interpolate each draw with FEModel.field_on_cells (the estimate's own map,
    independent of the 4-node shortcut) and take the sample std per cell.  With 20000 draws the std's relative
    standard error is 1 / sqrt(2 * 20000) = 0.5 %, so 3 % is 6 standard errors."""
    rng = np.random.default_rng(7)
    P = _random_covariance(fe.n, rng)
    draws = rng.multivariate_normal(np.zeros(fe.n), P, size=20000, method="cholesky")
    fields = np.stack([fe.field_on_cells(th) for th in draws])
    mc = fields.std(axis=0)
    sigma = FieldUncertainty(fe).field_sigma(P)
    assert sigma.shape == fields.shape[1:]
    np.testing.assert_allclose(sigma, mc, rtol=0.03)


def test_sigma_map_equals_the_dense_formula(fe: FEModel) -> None:
    """diag(M_theta P M_theta^T) written out (exact algebra, no sampling), with a representation error added in
    quadrature, and the fillet mean's sigma as sqrt(c_m^T P c_m + r^2)."""
    rng = np.random.default_rng(3)
    P = _random_covariance(fe.n, rng)
    r = 1.5
    unc = FieldUncertainty(fe, representation_rms=r)
    dense = np.einsum("ci,ij,cj->c", fe.M_theta, P, fe.M_theta) + r**2
    np.testing.assert_allclose(unc.field_sigma(P).ravel(), np.sqrt(dense), rtol=1e-12)
    assert unc.mean_sigma(P) == pytest.approx(np.sqrt(fe.c_m @ P @ fe.c_m + r**2), rel=1e-12)


def test_a_larger_state_is_read_by_its_node_block(fe: FEModel) -> None:
    """A calibrating filter's P has the parameters appended: only the node block may count."""
    rng = np.random.default_rng(5)
    P = _random_covariance(fe.n, rng)
    big = np.zeros((fe.n + 2, fe.n + 2))
    big[: fe.n, : fe.n] = P
    big[fe.n:, fe.n:] = 1e6  # huge parameter variance: would dominate if it leaked in
    unc = FieldUncertainty(fe)
    np.testing.assert_array_equal(unc.field_sigma(big), unc.field_sigma(P))
    assert unc.mean_sigma(big) == unc.mean_sigma(P)
