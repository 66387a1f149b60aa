"""Fixtures of the control tests: the small furnace (``cfg``) and its discrete model (eq. 12a) on the cached
tables (``model``); a test file that needs another furnace or model defines its own."""

from __future__ import annotations

import pytest

from twin.config import small_config


@pytest.fixture(scope="module")
def cfg():
    return small_config()


@pytest.fixture(scope="module")
def model(cfg, small_radiation):
    from twin.model.discrete import discrete_model

    return discrete_model(cfg, small_radiation, None)
