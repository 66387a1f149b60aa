"""The integrator's transfer at its edges (twin.control.lqg.carried_integrator): a group exactly at a bound, a
new integrator gain of zero on the free groups, a frozen integrator kept frozen.  Plans and gains are
test_bumpless's hand-made ones (3 states, 3 groups)."""

from __future__ import annotations

import numpy as np
import pytest

from tests.control.test_bumpless import _gains, _plan, n
from twin.control.lqg import IntegratorState, carried_integrator


@pytest.mark.parametrize("bound", [0.0, 1.0])
def test_a_group_exactly_at_a_bound_counts_as_clipped(bound) -> None:
    """Group 1's old input is exactly ``bound`` (unclipped value on the bound): it gives nothing to match, so
    groups 2 and 3 decide e_I' = -10 K s (group 1 alone would ask for -40 or +60)."""
    k = np.array([-0.01, -0.02, -0.01])
    old = _plan(np.array([bound - 0.2, 0.5, 0.6]), 1000.0)  # + k e_I = + 0.2 in group 1: exactly the bound
    new = _plan(np.array([0.6, 0.7, 0.7]), 1000.0)
    state = carried_integrator(old, _gains(0.0, k), new, _gains(0.0, k), 1.0, np.full(n, 1000.0),
                               IntegratorState(-20.0))
    assert state.e_I == pytest.approx(-10.0)


def test_every_group_clipped_keeps_the_integrator_and_its_freeze() -> None:
    k = np.array([-0.01, -0.02, -0.01])
    saturated = _plan(np.array([1.2, 1.3, 1.1]), 1000.0)
    new = _plan(np.array([0.99, 0.7, 0.7]), 1000.0)
    kept = carried_integrator(saturated, _gains(0.0, k), new, _gains(0.0, k), 1.0, np.full(n, 1000.0),
                              IntegratorState(-20.0, frozen=True))
    assert kept == IntegratorState(-20.0, frozen=True)


def test_a_new_plan_without_integral_action_on_the_free_groups_keeps_e_i() -> None:
    """k_new = 0 where the old input is free (group 1 is clipped and has k_new != 0): no e_I' can match
    anything, e_I stays."""
    old = _plan(np.array([1.1, 0.5, 0.6]), 1000.0)
    new = _plan(np.array([0.6, 0.7, 0.7]), 1000.0)
    state = carried_integrator(old, _gains(0.0, np.array([-0.01, -0.02, -0.01])), new,
                               _gains(0.0, np.array([-0.05, 0.0, 0.0])), 1.0, np.full(n, 1000.0),
                               IntegratorState(-20.0))
    assert state.e_I == -20.0
