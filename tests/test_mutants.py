"""A fixed handful of planted bugs that the suite must catch (the CI part of the mutation testing).

The full mutation run (``bash scripts/mutation.sh``, scores in docs/mutation.md, the full report in
test-artifacts/) takes too long for CI.  These mutants are the ones that matter most: the four one-line bugs
that once survived the
whole suite (the EKF's measurement gate, both anti-windup conditions, a run metric's window), places
mutmut does not mutate (decorated functions: the FE matrices; the net-radiation algebra outside its
scope) and the integrators and the model Jacobian, whose full mutation run is the longest.  Each is
planted by swapping the function's code object for one compiled from the edited source, the named
tests are run against it and must fail, and the original code is restored.
"""

from __future__ import annotations

import importlib
import inspect
import sys
import textwrap
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from functools import cached_property
from functools import partial as bind
from pathlib import Path
from typing import Any

import numpy as np

import twin.control.lqg as lqg
import twin.estimation.ekf as ekf
import twin.furnace.simulated.integrators as integrators
import twin.model.discrete as discrete
import twin.model.fe as fe
import twin.radiation.net_radiation as net_radiation
import twin.runs.metrics as metrics

TESTS = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Mutant:
    name: str
    function: Callable[..., Any]
    original: str
    mutated: str
    killers: tuple[Callable[..., Any], ...]  # tests (with their arguments bound) that must fail


def _code_owner(f: Any) -> Any:
    return f.func if isinstance(f, cached_property) else f


@contextmanager
def planted(m: Mutant) -> Iterator[None]:
    """The function with ``m.original`` replaced by ``m.mutated`` (exactly one occurrence) while inside."""
    owner = _code_owner(m.function)
    source = textwrap.dedent(inspect.getsource(owner))
    assert source.count(m.original) == 1, f"{m.name}: the original text is not in {owner.__qualname__} once"
    source = "\n".join(line for line in source.splitlines() if not line.lstrip().startswith("@"))
    namespace: dict[str, Any] = {}
    exec(compile(source.replace(m.original, m.mutated), inspect.getsourcefile(owner) or "<mutant>", "exec"),
         owner.__globals__, namespace)
    saved = owner.__code__
    owner.__code__ = namespace[owner.__name__].__code__
    try:
        yield
    finally:
        owner.__code__ = saved


def _killed(test: Callable[..., Any]) -> bool:
    try:
        test()
    except Exception:  # AssertionError, or the mutant breaking the computation outright
        return True
    return False


def _test_module(relative: str) -> Any:
    """A test module of this suite by its path under tests/ (the module pytest itself imports, if it did)."""
    path = TESTS / relative
    if str(path.parent) not in sys.path:  # pytest's rootdir import mode: each test folder on sys.path
        sys.path.insert(0, str(path.parent))
    module = importlib.import_module(path.stem)
    assert Path(module.__file__).resolve() == path.resolve()
    return module


def _mutants(small_radiation) -> list[Mutant]:
    t_ekf = _test_module("estimation/test_ekf.py")
    t_gate = _test_module("estimation/test_ekf_properties.py")
    t_fe = _test_module("model/test_fe.py")
    t_rad = _test_module("radiation/test_exchange_properties.py")
    t_metrics = _test_module("runs/test_metrics.py")
    t_lqg = _test_module("control/test_lqg.py")
    t_cond = _test_module("furnace/test_plant_conduction.py")
    t_plant = _test_module("furnace/test_plant_radiation.py")
    t_disc = _test_module("model/test_discrete.py")

    standin, cfg = t_lqg.make_standin(), t_lqg.small_config()
    enclosure = t_rad.enclosure_balance(small_radiation)  # from F^s only: no mutated code involved
    return [
        Mutant("gate: a reading at the gate is left out", ekf.ekf_update,
               "(normalized <= gate)", "(normalized < gate)",
               (bind(t_gate.test_a_reading_at_the_gate_is_used_and_beyond_it_left_out, 6.0, True),)),
        Mutant("gate: recovery with a single working TC", ekf.ekf_update,
               "finite.sum() >= 2", "finite.sum() >= 1",
               (bind(t_gate.test_recovery_needs_at_least_two_working_readings, [100.0, np.nan, np.nan], False),)),
        Mutant("Remark 5: frozen at 1^T u = delta0", lqg.integrator_delta,
               "float(u_applied.sum()) > delta0", "float(u_applied.sum()) >= delta0",
               (bind(t_lqg.test_remark5_total_power_threshold, [0.5, 0.5, 1.0], 1.0),)),
        Mutant("clamp rule: a group at exactly u = 1 counted as movable", lqg.integrator_delta,
               "(u_unclipped < 1.0)", "(u_unclipped <= 1.0)",
               (bind(t_lqg.test_clamp_rule_at_the_input_bounds, [1.0, 1.0], [-1.0, -1.0], -1.0, 0.0),)),
        Mutant("design: delta of Remark 5 ignored in the gains", lqg.anti_windup_delta,
               "0.0 if float(np.sum(u)) > delta0 else 1.0", "1.0",
               (bind(t_lqg.test_gains_use_delta_of_the_feedforward_at_every_sample, standin, cfg, 3),)),
        Mutant("metric: the steady sup-norm averaged over the wrong window", metrics.compute_metrics,
               'trf, stf = window(tf, t_E, "transient", t0), window(tf, t_E, "steady", t0)',
               'trf, stf = window(tf, t_E, "transient", t0), window(tf, t_E, "after_start", t0)',
               (t_metrics.test_each_metric_sees_only_its_window,)),
        Mutant("process noise: element-wise instead of matrix square", ekf.process_noise,
               "q0 * (S @ S)", "q0 * (S * S)", (t_ekf.test_process_noise_worked_example,)),
        Mutant("FE: conduction matrix without the y-direction term", fe.FEModel.__dict__["K"],
               "(np.kron(self._mass_y, kx) + np.kron(ky, self._mass_x))", "(np.kron(self._mass_y, kx))",
               # a new FEModel per call: K is a cached property
               (lambda: t_fe.test_mass_and_stiffness_match_textbook_element_matrices(t_fe.FEModel(cfg)),)),
        Mutant("AB2: the constant-step coefficient used with varying steps", integrators._advance_ab2,
               "r = h / (2.0 * prev.h)", "r = 0.5", (t_cond.test_ab2_keeps_second_order_with_varying_steps,)),
        Mutant("RK4: the stage weights dropped", integrators._advance_rk,
               "T += (h * bi) * ki", "T += (h / len(b)) * ki",
               (bind(t_plant.test_one_sub_step_is_the_textbook_step, cfg, small_radiation, "rk4"),)),
        Mutant("model: the radiation term's Jacobian 3 T^3 instead of 4 T^3 (eq. 16)", discrete.DiscreteModel.jac_theta,
               "(4.0 * self.t_s * T**3)", "(3.0 * self.t_s * T**3)",
               (lambda: t_disc.test_jacobians_match_finite_differences(
                   {"fixed": discrete.discrete_model(cfg, small_radiation, None)}, t_fe.FEModel(cfg), "fixed"),)),
        Mutant("radiation: P2 without the lamp surface scale", net_radiation.specimen_matrices,
               "P2_faces = X * lamp_flux_scale[None, :]", "P2_faces = X",
               (bind(t_rad.test_the_specimens_share_is_the_models_P2, enclosure, small_radiation),)),
    ]


def test_the_suite_catches_the_planted_bugs(small_radiation) -> None:
    survivors = []
    for m in _mutants(small_radiation):
        for test in m.killers:  # first: the test passes on the real code (it can pass at all)
            test()
        with planted(m):
            if not all(_killed(test) for test in m.killers):
                survivors.append(m.name)
    assert not survivors, f"planted bugs not caught: {survivors}"


def test_planting_swaps_and_restores_the_code() -> None:
    m = Mutant("demo", metrics.window, 'which == "steady"', 'which == "STEADY"', ())
    t = np.linspace(0, 20, 201)
    before = metrics.window(t, 10.0, "steady").sum()
    with planted(m):
        inside = metrics.window(t, 10.0, "steady").sum()
    assert before == 51 and inside == 191  # an unknown name falls through to the after-start window
    assert metrics.window(t, 10.0, "steady").sum() == 51
    # an equivalent edit is not "caught": the check can report a survivor
    same = Mutant("equivalent", ekf.process_noise, "q0 * (S @ S)", "(S @ S) * q0", ())
    t_ekf = _test_module("estimation/test_ekf.py")
    with planted(same):
        assert not _killed(t_ekf.test_process_noise_worked_example)


def test_the_equivalence_rules_of_the_mutation_report_are_well_formed() -> None:
    """scripts/mutation_equivalent.toml parses, every entry has a reason, every pattern compiles, and
    the rules accept what they describe and nothing next to it (scripts/mutation_report.py)."""
    import re

    sys.path.insert(0, str(TESTS.parent / "scripts"))
    try:
        import mutation_report as mr
    finally:
        sys.path.remove(str(TESTS.parent / "scripts"))
    by_name, rules = mr.load_equivalents()
    assert rules and all(r["reason"].strip() for r in [*rules, *by_name.values()])
    for rule in rules:
        assert rule.get("strings_only") or rule["subs"], rule["reason"][:40]
        for pattern, _ in rule.get("subs", []):
            re.compile(pattern)
        re.compile(rule.get("where", ""))
    dtype = next(r for r in rules if r["reason"].startswith("The dtype argument"))
    assert mr._rule_pair("v = np.asarray(x, float)", "v = np.asarray(x, None)", dtype)
    assert not mr._rule_pair("v = np.asarray(x, float)", "v = np.asarray(float)", dtype)  # not a dtype change
    assert not mr._rule_pair("v = np.asarray(x, float)", "v = np.asarray(None, float)", dtype)
