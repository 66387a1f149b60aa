"""Exchange-factor table: reproducibility, disk cache, precompute entry points."""

from __future__ import annotations

import logging
import time

import numpy as np
import pytest

from twin.config import small_config
from twin.furnace.simulated.truth import precompute_truth, truth_radiation_config
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
    # the CLI's second table: the simulated furnace's own, a symmetric trace cached beside the model's
    few = tiny.with_overrides({"truth.radiation.rays_per_specimen_cell": 40, "truth.radiation.rays_per_lamp": 600,
                               "truth.radiation.rays_per_wall": 600})
    precompute_truth(few)
    own = truth_radiation_config(few)
    assert sorted(tmp_path.glob("*.npz")) == sorted([cache_path(tiny), cache_path(own, symmetric=True)])
    assert precompute_seconds(own, symmetric=True) > 0


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


def _children(pid: int) -> set[int]:
    """Processes whose parent is ``pid`` (Linux /proc)."""
    from pathlib import Path

    out = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.add(int(stat.parent.name))
    return out


def _alive(pid: int) -> bool:
    """The process exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def test_ray_tracing_workers_die_with_a_killed_parent(tmp_path):
    """A server killed during a cold ray trace must not leave workers that hold the cache lock."""
    import fcntl
    import signal
    import subprocess
    import sys

    script = (
        "import sys\n"
        "from twin.config import small_config\n"
        "from twin.radiation.cache import load_or_compute\n"
        "cfg = small_config().with_overrides({'radiation.rays_per_specimen_cell': 4000})\n"
        "load_or_compute(cfg, cache_dir=sys.argv[1])\n"
    )
    proc = subprocess.Popen([sys.executable, "-c", script, str(tmp_path)])
    try:
        deadline = time.monotonic() + 120.0  # imports and geometry first; the machine may be loaded
        workers: set[int] = set()
        while len(workers) < 2 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.1)
            workers = _children(proc.pid)
        assert len(workers) == 2, "the ray trace did not start its two workers"
        time.sleep(0.5)  # the workers are inside their first position (seconds each at 4000 rays per cell)
    finally:
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    deadline = time.monotonic() + 10.0
    while workers and time.monotonic() < deadline:
        workers = {w for w in workers if _alive(w)}
        time.sleep(0.1)
    assert not workers, f"orphaned ray-tracing workers {workers}"
    locks = list(tmp_path.glob("*.lock"))
    assert locks
    with open(locks[0], "w") as fh:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)  # raises BlockingIOError while an orphan holds it


def test_matrices_for_another_emissivity_are_built_once_and_equal_a_build(tiny, tmp_path, monkeypatch, caplog):
    """with_specimen_emissivity of a cached table (the plant's mismatch, the model's emissivity sensitivity):
    the first call builds P1, P2 (eq. 5) and keeps them beside the table, later ones (another process: a new
    model) read them back equal to the bit to what a build gives; a different eps is its own file; an
    unreadable file is rebuilt (issue 21: a run built them three times)."""
    import twin.radiation.model as model_module
    from twin.radiation.cache import emissivity_path
    from twin.radiation.model import build_matrices

    builds = []
    real = model_module.build_matrices
    monkeypatch.setattr(model_module, "build_matrices", lambda F, o: builds.append(1) or real(F, o))
    rad = radiation_model(tiny, cache_dir=tmp_path)
    eps = tiny.specimen.emissivity * 1.02
    first = rad.with_specimen_emissivity(eps)
    again = radiation_model(tiny, cache_dir=tmp_path).with_specimen_emissivity(eps)
    assert len(builds) == 1 and emissivity_path(rad.cache_file, eps).is_file()
    expected = build_matrices(rad.exchange, rad.optics.with_specimen_emissivity(eps))  # the oracle: a fresh build
    for got in (first, again):
        assert got.P1.tobytes() == expected[0].tobytes() and got.P2.tobytes() == expected[1].tobytes()
    assert not np.array_equal(rad.with_specimen_emissivity(eps * 1.01).P1, first.P1) and len(builds) == 2
    emissivity_path(rad.cache_file, eps).write_bytes(b"not an npz")
    with caplog.at_level(logging.WARNING):
        rebuilt = rad.with_specimen_emissivity(eps)
    assert "unreadable emissivity matrices" in caplog.text and len(builds) == 3
    assert rebuilt.P1.tobytes() == expected[0].tobytes()
