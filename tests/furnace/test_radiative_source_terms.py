"""The plant's radiative source q_r of eq. (4) term by term, against the equation written out here.

    q_r = P1(eta) [T^4; T_w^4] + P2(eta) u_lamp,     P(eta) = (1 - w) P_k + w P_{k+1}

on a hand-made table (three positions, two walls at known temperatures, random entries), so every
term can be told apart: the specimen's emission, the walls' constant column, the lamps per group and
per lamp, the lamp scale (1 + lamp-efficiency deviation), and the interpolation at both ends of the
table, where the hat weight is exactly 0 or exactly 1.  The oracle is float64 numpy on the raw tables;
the plant's specimen block runs in float32 (its docstring), hence a tolerance of 2e-6 of the largest
sum_j |P1_kj| T_j^4 (float32's 6e-8 times about 30 terms, with margin).
"""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated.radiative_source import PlantRadiation

ETA = np.array([-0.02, 0.0, 0.03])  # m, uneven on purpose
T_WALL = np.array([420.0, 610.0])  # K


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def table(cfg):
    rng = np.random.default_rng(23)
    n, n_lamps = cfg.specimen.n_states, cfg.lamps.n_lamps
    P1 = rng.uniform(-1e-8, 1e-8, (len(ETA), n, n + len(T_WALL)))
    P2 = rng.uniform(-0.3, 0.0, (len(ETA), n, n_lamps))
    flux_max = rng.uniform(1e4, 3e4, n_lamps)
    return SimpleNamespace(P1=P1, P2=P2, eta_nodes=ETA, wall_temperatures=T_WALL, lamp_flux_max=flux_max)


def _at(M, eta):
    """M(eta) by the hat functions: np.interp per entry (independent of twin.physics.motion)."""
    flat = M.reshape(len(ETA), -1)
    return np.array([np.interp(eta, ETA, flat[:, j]) for j in range(flat.shape[1])]).reshape(M.shape[1:])


def _oracle(table, cfg, T, u_lamps, eta, lamp_scale=1.0):
    n = cfg.specimen.n_states
    P1 = _at(table.P1, eta)
    P2 = _at(table.P2, eta)
    return (P1[:, :n] @ T**4 + P1[:, n:] @ T_WALL**4
            + P2 @ (lamp_scale * table.lamp_flux_max * u_lamps))


def _temperatures(cfg):
    return np.linspace(700.0, 1150.0, cfg.specimen.n_states)


def _float32_tol(table, cfg, T):
    """What the float32 specimen block may round: 2e-6 (float32's 6e-8 times ~30 terms) of sum_j |P1_kj| T_j^4."""
    n = cfg.specimen.n_states
    return 2e-6 * float((np.abs(table.P1[:, :, :n]).max(axis=0) @ T**4).max())


@pytest.mark.parametrize("eta", [ETA[0], -0.005, 0.0, 0.012, ETA[-1]])
def test_flux_per_group_is_eq_4_at_the_table_ends_on_a_node_and_between(table, cfg, eta) -> None:
    # ETA[0]: w = 0 in the first interval; ETA[-1]: w = 1 in the last one (its own block, not the one before)
    src = PlantRadiation(cfg, table)
    u = np.array([0.9, 0.0, 0.35, 0.6, 0.1, 1.0])
    T = _temperatures(cfg)
    want = _oracle(table, cfg, T, cfg.group_matrix @ u, eta)
    got = src.flux(T, np.append(u, 1.0), False, eta)
    np.testing.assert_allclose(got, want, rtol=0, atol=_float32_tol(table, cfg, T))


@pytest.mark.parametrize("eta", [ETA[0], 0.012, ETA[-1]])
def test_flux_per_lamp_uses_each_lamps_own_column(table, cfg, eta) -> None:
    # a failed lamp inside a group (Plant.inputs gives per-lamp fractions then): the lamps of one group differ
    src = PlantRadiation(cfg, table)
    u_lamps = np.linspace(0.0, 1.0, cfg.lamps.n_lamps)
    T = _temperatures(cfg)
    want = _oracle(table, cfg, T, u_lamps, eta)
    np.testing.assert_allclose(src.flux(T, np.append(u_lamps, 1.0), True, eta), want, rtol=0,
                               atol=_float32_tol(table, cfg, T))
    lamps_only = _at(table.P2, eta) @ (table.lamp_flux_max * u_lamps)
    np.testing.assert_allclose(src.lamp_flux(u_lamps, True, eta), lamps_only, rtol=1e-12)
    groups = np.array([0.2, 0.5, 1.0, 0.0, 0.7, 0.3])
    np.testing.assert_allclose(src.lamp_flux(groups, False, eta),
                               _at(table.P2, eta) @ (table.lamp_flux_max * (cfg.group_matrix @ groups)), rtol=1e-12)


def test_the_lamp_scale_scales_the_lamps_only_and_is_one_by_default(table, cfg) -> None:
    T, eta = _temperatures(cfg), 0.012
    u = np.full(cfg.group_matrix.shape[1], 0.5)
    plain, scaled = PlantRadiation(cfg, table), PlantRadiation(cfg, table, lamp_scale=0.85)
    lamps = _at(table.P2, eta) @ (table.lamp_flux_max * (cfg.group_matrix @ u))
    np.testing.assert_allclose(plain.lamp_flux(u, False, eta), lamps, rtol=1e-12)  # default: lamp_scale 1
    np.testing.assert_allclose(scaled.lamp_flux(u, False, eta), 0.85 * lamps, rtol=1e-12)
    # emission and walls do not scale: the difference of the two fluxes is the lamps' 15 %
    v1 = np.append(u, 1.0)
    np.testing.assert_allclose(plain.flux(T, v1, False, eta) - scaled.flux(T, v1, False, eta), 0.15 * lamps,
                               rtol=0, atol=2 * _float32_tol(table, cfg, T))


def test_a_table_without_walls_is_accepted_and_one_that_does_not_fit_the_plate_is_not(table, cfg) -> None:
    n = cfg.specimen.n_states
    no_walls = SimpleNamespace(**{**vars(table), "P1": table.P1[:, :, :n], "wall_temperatures": np.zeros(0)})
    src = PlantRadiation(cfg, no_walls)  # N_s + 0 columns: the specimen block alone
    T, eta = _temperatures(cfg), 0.0
    np.testing.assert_allclose(src.flux(T, np.append(np.zeros(cfg.group_matrix.shape[1]), 1.0), False, eta),
                               table.P1[1, :, :n] @ T**4, rtol=0, atol=_float32_tol(table, cfg, T))
    short = SimpleNamespace(**{**vars(no_walls), "P1": table.P1[:, :, : n - 1]})
    with pytest.raises(ValueError, match="plant has"):
        PlantRadiation(cfg, short)
    rows = SimpleNamespace(**{**vars(table), "P1": table.P1[:, 1:, :]})  # one row short, columns plenty
    with pytest.raises(ValueError, match="plant has"):
        PlantRadiation(cfg, rows)


def test_matrices_are_the_weighted_tables_in_float64(table, cfg) -> None:
    n = cfg.specimen.n_states
    src = PlantRadiation(cfg, table)
    w = [0.2, 0.5, 0.3]  # period-averaged weights (eq. 11b): a list of floats
    P1s, q_wall, P2g = src.matrices(w)
    np.testing.assert_allclose(P1s, np.tensordot(w, table.P1[:, :, :n], axes=1), rtol=1e-13)
    np.testing.assert_allclose(q_wall, np.tensordot(w, table.P1[:, :, n:] @ T_WALL**4, axes=1), rtol=1e-13)
    np.testing.assert_allclose(P2g, np.tensordot(w, table.P2 * table.lamp_flux_max, axes=1) @ cfg.group_matrix,
                               rtol=1e-13)
    assert P1s.dtype == np.float64
