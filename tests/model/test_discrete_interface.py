"""The discrete model's interface to the OCP and to the hold (twin.model.discrete.DiscreteModel): the CasADi
function the OCP builds on (its names, its kind, its values against ``step``) and where ``hold_powers`` refuses.

Oracles: ``step`` (eq. 12a, tested against the FE model in test_discrete.py) for the CasADi function's values;
the model's own steady state at a known power for the hold's bounds.
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.config import small_config
from twin.model.discrete import discrete_model
from twin.scenario import OscillationSpec

CFG = small_config()


@pytest.fixture(scope="module")
def model(small_radiation):
    return discrete_model(CFG, small_radiation, None)


def test_the_casadi_step_is_named_for_the_ocp_and_equals_step(model) -> None:
    theta = np.linspace(700.0, 1100.0, model.n)
    u = np.linspace(0.1, 0.9, model.m)
    for kind, cls in (("MX", "MXFunction"), ("SX", "SXFunction")):
        F = model.casadi_step(kind)
        assert F.is_a(cls) and F.name() == "F"
        assert F.name_in() == ["theta", "u"] and F.name_out() == ["theta_next"]
        by_name = F(theta=theta, u=u)["theta_next"]  # the OCP calls it by its names
        np.testing.assert_allclose(np.asarray(by_name).ravel(), model.step(theta, u), rtol=1e-12)
    assert model.casadi_step().is_a("MXFunction")  # MX unless asked


def test_an_oscillating_model_keeps_its_motion(small_radiation) -> None:
    osc = OscillationSpec(enabled=True, amplitude=0.02, period=4.0)
    assert discrete_model(CFG, small_radiation, osc).oscillation is osc
    assert discrete_model(CFG, small_radiation, None).oscillation is None


def test_hold_powers_refuses_a_mean_that_needs_more_than_full_power(model) -> None:
    """With the distribution d = (2, 1, ..., 1) (its largest share 2), the mean the model settles at for u = 0.8 d
    (1.6 of u_max in the first group) cannot be held; for u = 0.45 d (0.9) it is, with exactly that u."""
    d = np.ones(model.m)
    d[0] = 2.0
    over = float(model.c_m @ model.steady_state(0.8 * d))
    with pytest.raises(ValueError, match=f"T_mean = {over} K needs more than u_max with this distribution"):
        model.hold_powers(over, d)
    within = float(model.c_m @ model.steady_state(0.45 * d))
    np.testing.assert_allclose(model.hold_powers(within, d), 0.45 * d, rtol=1e-8)
    # the same mean with every group equal needs less than full power: held
    u = model.hold_powers(within)
    assert u.max() < 1.0 and np.ptp(u) == 0.0
