"""Second look at the motion mutants written off as equivalent (scripts/mutation_equivalent.toml, issue 23).

Random increasing tables (1-15 nodes, symmetric or not, in m and in mm, as float64 arrays, lists and
float32), hat weights at random positions, on nodes and at the ends, and period-average weights for
amplitudes from 0 to the shorter side.  Prints a digest of every result (values, dtypes, exceptions by type)
and the number of warnings.  Run inside mutmut's ``mutants/`` folder once for the original and once per
mutant::

    cd mutants && MUTANT_UNDER_TEST='twin.physics.motion.x_hat_weights__mutmut_16' \\
        ../.venv/bin/python ../scripts/mutation_second_look_motion.py
"""

from __future__ import annotations

import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.getcwd())  # mutants/: the mutated twin with its trampolines
from mutation_second_look import out, rec, report  # noqa: E402  (the shared record, scripts/mutation_second_look.py)

from twin.physics.motion import hat_weights, oscillation_weights  # noqa: E402


def scenario(seed: int) -> int:
    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 16))
    scale = 1000.0 if seed % 5 == 0 else 1.0
    if seed % 3 == 0:
        nodes = np.linspace(-0.05, 0.05, n) * scale
    else:
        nodes = (np.cumsum(rng.uniform(0.1, 1.0, n)) / n * 0.1 - rng.uniform(0.01, 0.09)) * scale
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for table in (nodes, nodes.tolist(), nodes.astype(np.float32)):
            pos = [*table[:], float(table[0]), float(table[-1]), *rng.uniform(table[0], table[-1], 8)]
            for eta in pos:
                try:
                    rec(hat_weights(table, eta))
                except ValueError as e:
                    out.append(type(e).__name__)
            a_max = max(min(-float(table[0]), float(table[-1])), 0.0)
            for a in (0.0, a_max, *rng.uniform(0.0, 1.0, 6) * a_max):
                try:
                    rec(oscillation_weights(np.asarray(table), a))
                except ValueError as e:
                    out.append(type(e).__name__)
    return len(caught)


if __name__ == "__main__":
    report(scenario, 300)
