"""Second look at the plan mutants written off as equivalent (scripts/mutation_equivalent.toml, issue 23).

v_at with knots and values as float64 / float32 / int arrays and lists and run times as floats, ints,
float32 and lists (at, between and outside the knots); simulate with initial states as lists of ints,
float32 and float64 on an affine stand-in model.  Prints a digest of every result (values and dtypes).
Run inside mutmut's ``mutants/`` folder once for the original and once per mutant::

    cd mutants && MUTANT_UNDER_TEST='twin.control.plan.xǁFeedforwardPlanǁv_at__mutmut_3' \\
        ../.venv/bin/python ../scripts/mutation_second_look_plan.py
"""

from __future__ import annotations

import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.getcwd())  # mutants/: the mutated twin with its trampolines
from mutation_second_look import rec, report  # noqa: E402  (the shared record, scripts/mutation_second_look.py)

from twin.control.plan import FeedforwardPlan, simulate  # noqa: E402


class _Affine:
    n = 2

    def step(self, theta, u):
        return 0.9 * np.asarray(theta, float) + np.array([[0.5], [0.25]]) @ np.asarray(u, float)


def scenario(seed: int) -> int:
    rng = np.random.default_rng(seed)
    K = int(rng.integers(1, 6))
    knots = np.cumsum(rng.integers(1, 20, K + 1)).astype(float)
    v = rng.uniform(0.0, 1.0, K)
    plan = FeedforwardPlan(t=np.arange(3.0), u_ff=np.zeros((2, 1)), theta_ref=np.zeros((3, 2)), T_ref=np.zeros(3),
                           T_mean=np.zeros(3), status="x", iterations=0, solve_s=0.0, success=True)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for tk in (knots, knots.astype(np.float32), knots.astype(int), knots.tolist()):
            for vv in (v, v.astype(np.float32), np.rint(10 * v).astype(int), v.tolist()):
                p = FeedforwardPlan(**{**plan.__dict__, "warm": {"t_knots": tk, "v": vv}})
                ts = np.concatenate([knots, knots + 0.5, [knots[0] - 3, knots[-1] + 7]])
                for t in (ts, ts.astype(np.float32), np.rint(ts).astype(int), ts.tolist(), float(ts[1]), int(ts[0])):
                    rec(p.v_at(t))
        u = rng.uniform(0, 1, (4, 1))
        for theta0 in ([1, 2], np.array([1.5, 2.5], np.float32), np.array([1.5, 2.5])):
            rec(simulate(_Affine(), theta0, u))
    return len(caught)


if __name__ == "__main__":
    report(scenario, 100)
