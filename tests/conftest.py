"""Shared test fixtures: the test radiation cache (computed once, reused by every test run)."""

from __future__ import annotations

import importlib.util
import os
import sys
from collections.abc import Callable
from pathlib import Path
from types import ModuleType

import pytest
from hypothesis import HealthCheck, settings

# The peers of the interoperability tests run on o6 (open62541) in processes of their own: importing o6 starts a
# timer that ends its process ten minutes later, so nothing of theirs may be imported here (--doctest-modules)
collect_ignore = ["furnace/o6_peers"]

# Property tests (hypothesis): deterministic (derandomize: CI sees the same examples every run, no
# example database), a bounded number of examples, and a per-example deadline generous enough for a
# loaded 2-core machine (the slowest examples take ~0.2 s on a machine at load 20; 10 s only catches
# a runaway, never a busy neighbour).
settings.register_profile(
    "furnace",
    max_examples=40,
    deadline=10_000,
    derandomize=True,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    print_blob=False,
)
settings.load_profile("furnace")

REPO = Path(__file__).resolve().parents[1]
TEST_RADIATION_CACHE = REPO / ".cache" / "test-radiation"  # also set for the whole session in ../conftest.py


@pytest.fixture(scope="session", autouse=True)
def single_threaded_blas():
    """Limit BLAS / OpenMP pools to one thread for the whole test session."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1):
        yield


@pytest.fixture(scope="session", autouse=True)
def radiation_cache() -> Path:
    """The F^s cache directory of the test suite (``<repo>/.cache/test-radiation``)."""
    os.environ["FURNACE_TWIN_CACHE"] = str(TEST_RADIATION_CACHE)
    TEST_RADIATION_CACHE.mkdir(parents=True, exist_ok=True)
    return TEST_RADIATION_CACHE


#: the loaded test radiation model, kept for the life of the process: a mutation run
#: (scripts/mutation.sh) forks one pytest session per mutant from a process that already loaded it
_RADIATION: dict[str, object] = {}


@pytest.fixture(scope="session")
def small_radiation(radiation_cache):
    """``radiation_model(small_config())`` from the test cache (ray-traced on first use)."""
    from twin.config import small_config
    from twin.radiation import radiation_model

    key = str(radiation_cache)
    if key not in _RADIATION:
        _RADIATION[key] = radiation_model(small_config(), cache_dir=radiation_cache)
    return _RADIATION[key]


@pytest.fixture(scope="session")
def small_truth_radiation(radiation_cache):
    """The simulated furnace's own table of ``small_config()`` (``[truth.radiation]``, symmetric trace), kept
    like the model's."""
    from twin.config import small_config
    from twin.furnace.simulated.truth import truth_radiation

    key = f"truth:{radiation_cache}"
    if key not in _RADIATION:
        _RADIATION[key] = truth_radiation(small_config(), cache_dir=radiation_cache)
    return _RADIATION[key]


@pytest.fixture(scope="session")
def load_script() -> Callable[[str], ModuleType]:
    """``load_script("control_table")``: the module ``scripts/control_table.py`` (``scripts/`` is not a package),
    registered in ``sys.modules`` under its name (a dataclass of the module looks itself up there); loaded once."""

    def load(name: str) -> ModuleType:
        if name not in sys.modules:
            spec = importlib.util.spec_from_file_location(name, REPO / "scripts" / f"{name}.py")
            assert spec is not None and spec.loader is not None
            module = importlib.util.module_from_spec(spec)
            sys.modules[name] = module
            spec.loader.exec_module(module)
        return sys.modules[name]

    return load
