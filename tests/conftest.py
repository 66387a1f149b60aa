"""Shared test fixtures: the test radiation cache (computed once, reused by every test run)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

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


@pytest.fixture(scope="session")
def small_radiation(radiation_cache):
    """``radiation_model(small_config())`` from the test cache (ray-traced on first use)."""
    from twin.config import small_config
    from twin.radiation import radiation_model

    return radiation_model(small_config(), cache_dir=radiation_cache)
