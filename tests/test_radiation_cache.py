"""Exchange-factor table: reproducibility, disk cache, precompute entry points."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest

from twin.config import small_config
from twin.radiation import radiation_model
from twin.radiation.cache import cache_path, load_or_compute, precompute_command, precompute_seconds
from twin.radiation.exchange import eta_nodes, exchange_factor_table


@pytest.fixture(scope="module")
def tiny():
    """A coarse plate with a handful of rays: the pipeline, not the accuracy, is tested here."""
    return small_config().with_overrides(
        {
            "specimen.nx": 6,
            "specimen.ny": 5,
            "radiation.rays_per_specimen_cell": 20,
            "radiation.rays_per_lamp": 300,
            "radiation.rays_per_wall": 300,
            "oscillation.positions": 3,
        }
    )


def test_eta_nodes_follow_the_paper(tiny):
    # eta_n = -eta_bar + (n - 1) 2 eta_bar / N_eta (paper section 2.1)
    np.testing.assert_allclose(eta_nodes(tiny), [-0.05, 0.0, 0.05])
    assert eta_nodes(tiny.with_overrides({"oscillation.eta_max": 0.0})).tolist() == [0.0]


def test_table_does_not_depend_on_the_number_of_workers(tiny):
    eta1, F1 = exchange_factor_table(tiny, workers=1)
    eta2, F2 = exchange_factor_table(tiny, workers=2)
    np.testing.assert_array_equal(eta1, eta2)
    np.testing.assert_array_equal(F1, F2)


def test_cache_roundtrip_and_key(tiny, tmp_path):
    t0 = time.perf_counter()
    first = load_or_compute(tiny, cache_dir=tmp_path)
    cold = time.perf_counter() - t0
    path = cache_path(tiny, tmp_path)
    assert path.exists() and not list(tmp_path.glob("*.tmp"))
    t0 = time.perf_counter()
    again = load_or_compute(tiny, cache_dir=tmp_path)
    warm = time.perf_counter() - t0
    np.testing.assert_array_equal(first.F, again.F)
    np.testing.assert_array_equal(first.P1, again.P1)
    assert warm < cold
    # anything F^s depends on changes the key; the sampling time does not
    assert cache_path(tiny.with_overrides({"radiation.seed": 1}), tmp_path) != path
    assert cache_path(tiny.with_overrides({"housing.sections": 4}), tmp_path) != path
    assert cache_path(tiny.with_overrides({"sampling.t_s": 0.2}), tmp_path) == path


def test_corrupt_cache_is_recomputed(tiny, tmp_path, caplog):
    path = cache_path(tiny, tmp_path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(b"not an npz")
    with caplog.at_level(logging.WARNING):
        table = load_or_compute(tiny, cache_dir=tmp_path)
    assert "unreadable radiation cache" in caplog.text
    assert table.F.shape[0] == 3
    assert load_or_compute(tiny, cache_dir=tmp_path).F.shape == table.F.shape


def test_radiation_model_from_cache(tiny, tmp_path):
    rad = radiation_model(tiny, cache_dir=tmp_path)
    s = tiny.specimen
    n_w = 4 + tiny.housing.sections
    assert rad.P1.shape == (3, s.n_states, s.n_states + n_w)
    assert rad.P2.shape == (3, s.n_states, tiny.lamps.n_lamps)
    assert len(rad.wall_names) == n_w == len(rad.wall_temperatures)
    # u_max = p_el / (pi d l) (paper, after eq. 2): 2 kW on a 10 mm x 0.26 m tube
    assert rad.lamp_flux_max[0] == pytest.approx(2000.0 / (np.pi * 0.010 * 0.26))


def test_precompute_entry_points(tiny, tmp_path, monkeypatch, caplog):
    monkeypatch.setenv("FURNACE_TWIN_CACHE", str(tmp_path))
    with caplog.at_level(logging.INFO):
        assert precompute_command(tiny, force=False) == 0
        assert precompute_command(tiny, force=False) == 0
    assert str(cache_path(tiny)) in caplog.text and "up to date" in caplog.text
    seconds = precompute_seconds(tiny)
    assert seconds > 0
    assert list(tmp_path.glob("*.npz")) == [cache_path(tiny)]  # the bench leaves no file behind


def test_fixed_specimen_and_single_housing_section(tiny, tmp_path):
    # no oscillation: one table position, weights [1] for any eta; one housing section holds all walls
    cfg = tiny.with_overrides({"oscillation.eta_max": 0.0, "oscillation.positions": 1, "housing.sections": 1})
    rad = radiation_model(cfg, cache_dir=tmp_path)
    assert rad.eta_nodes.tolist() == [0.0] and rad.weights(0.01).tolist() == [1.0]
    assert rad.wall_names == ("reflector_h", "reflector_v", "housing_1", "holder_upper", "holder_lower")
    T = np.full(cfg.specimen.n_states, 600.0)
    # isothermal enclosure exchanges nothing (reciprocity + closure), float32 storage ~1e-6
    q = rad.flux(T, np.zeros(cfg.lamps.n_lamps), 0.0, T_w=np.full(5, 600.0))
    assert np.max(np.abs(q)) < 1e-5 * 5.670374419e-8 * 600.0**4
