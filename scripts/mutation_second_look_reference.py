"""Second look at the reference mutants written off as equivalent (scripts/mutation_equivalent.toml, issue 23).

Random transitions and point references (1-6 points, with and without a point at 0, start times 0..50 s),
evaluated with __call__ and rate at times before, at and after t_start and t_end, inside, as floats, ints,
float32 and NaN; steady states of stand-in models (linear and bilinear, several nodes) whose step and
jac_theta return arrays or lists, from guesses as lists of ints, float32 and float64.  Prints a digest of
every result (values and dtypes, exceptions by type) and the number of warnings.  Run inside mutmut's
``mutants/`` folder once for the original and once per mutant::

    cd mutants && MUTANT_UNDER_TEST='twin.control.reference.x__points__mutmut_73' \\
        ../.venv/bin/python ../scripts/mutation_second_look_reference.py
"""

from __future__ import annotations

import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.getcwd())  # mutants/: the mutated twin with its trampolines
from mutation_second_look import out, rec, report  # noqa: E402  (the shared record, scripts/mutation_second_look.py)

from twin.control.reference import reference_trajectory, steady_state  # noqa: E402
from twin.scenario import PointsReference, TransitionReference  # noqa: E402


class _Model:
    def __init__(self, n: int, rng: np.random.Generator, lists: bool, bilinear: bool) -> None:
        self.n, self.m, self.lists, self.bilinear = n, 1, lists, bilinear
        self.a = rng.uniform(0.1, 0.9, n)
        self.b = rng.uniform(300.0, 1500.0, n)

    def step(self, theta, u):
        g = self.a * (1.0 + (u[0] if self.bilinear else 0.0))
        r = theta + g * (self.b * (0.5 + u[0]) - theta)
        return r.tolist() if self.lists else r

    def jac_theta(self, theta, u):
        g = self.a * (1.0 + (u[0] if self.bilinear else 0.0))
        J = np.diag(1.0 - g)
        return J.tolist() if self.lists else J


def scenario(seed: int) -> int:
    rng = np.random.default_rng(seed)
    t_start = float(rng.choice([0.0, rng.uniform(0, 50)]))
    T0 = float(rng.uniform(300, 1200))
    if seed % 2:
        spec = TransitionReference(setpoint=float(rng.uniform(300, 1300)), t_E=float(rng.uniform(1, 300)))
    else:
        k = int(rng.integers(1, 7))
        ts = np.cumsum(rng.uniform(1, 100, k)) - (rng.uniform(1, 100) if seed % 4 == 0 else 0.0)
        ts = ts - ts[0] if seed % 4 == 0 else ts
        spec = PointsReference(points=[(float(t), float(rng.uniform(300, 1300))) for t in ts])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        ref = reference_trajectory(spec, T0, t_start=t_start)
        t = np.concatenate([[ref.t_start, ref.t_end, ref.t_start - 1, ref.t_end + 1, -5.0, 1e5, np.nan],
                            rng.uniform(ref.t_start - 10, ref.t_end + 10, 20)])
        for tt in (t, t.astype(np.float32), np.rint(np.nan_to_num(t)).astype(int), float(t[0]), t.tolist()):
            rec(ref(tt))
            rec(ref.rate(tt))
        n = int(rng.integers(1, 4))
        model = _Model(n, rng, lists=bool(seed % 3 == 0), bilinear=bool(seed % 5 == 0))
        for guess in (np.rint(model.b * 0.5).astype(int).tolist(), (model.b * 0.7).astype(np.float32), model.b * 3):
            for u in ([0.5], np.array([1], int), np.array([0.25], np.float32)):
                try:
                    rec(steady_state(model, u, guess))
                except ValueError as e:
                    out.append(type(e).__name__)
    return len(caught)


if __name__ == "__main__":
    report(scenario, 200)
