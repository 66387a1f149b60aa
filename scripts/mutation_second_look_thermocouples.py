"""Second look at the thermocouple mutants written off as equivalent (scripts/mutation_equivalent.toml).

Grids of 1-7 x 1-7 cells (also one-cell rows and columns) and sizes from mm to m, positions at random, on
the corners, edges and cell centres; fields as float64, float32, ints and lists.  Prints a digest of every
interpolation matrix, reading (noise 0 and 0.5 from a seeded generator) and exception, and the number of
warnings.  Run inside mutmut's ``mutants/`` folder once for the original and once per mutant::

    cd mutants && MUTANT_UNDER_TEST='twin.furnace.simulated.thermocouples.x_interpolation_matrix__mutmut_32' \\
        ../.venv/bin/python ../scripts/mutation_second_look_thermocouples.py
"""

from __future__ import annotations

import os
import sys
import warnings
from types import SimpleNamespace

import numpy as np

sys.path.insert(0, os.getcwd())  # mutants/: the mutated twin with its trampolines
from mutation_second_look import out, report  # noqa: E402  (the shared record and digest)

from twin.furnace.simulated.thermocouples import Thermocouples, interpolation_matrix  # noqa: E402


def rec(x: object) -> None:
    x = np.asarray(x)
    out.append((x.shape, x.astype(float).tobytes()))  # values (the positions' dtype is tested, not compared)


def scenario(seed: int) -> int:
    rng = np.random.default_rng(seed)
    nx, ny = int(rng.integers(1, 8)), int(rng.integers(1, 8))
    L, W = rng.uniform(0.001, 1.0, 2)
    cfg = SimpleNamespace(specimen=SimpleNamespace(length=L, width=W, nx=nx, ny=ny))
    xc, yc = (np.arange(nx) + 0.5) * L / nx, (np.arange(ny) + 0.5) * W / ny
    pts = [(0.0, 0.0), (L, W), (0.0, W), (L, 0.0), (xc[-1], yc[0]), (xc[0], yc[-1]), (L / 2, W / 2)]
    pts += [tuple(p) for p in rng.uniform([0, 0], [L, W], (6, 2))]
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            rec(interpolation_matrix(cfg, pts))
            tcs = Thermocouples(cfg, pts)
            rec(tcs.positions)
            T = rng.uniform(300.0, 1300.0, nx * ny)
            for field in (T, T.astype(np.float32), np.rint(T).astype(int), list(T)):
                rec(tcs.true_values(field))
                rec(tcs.read(field, np.random.default_rng(seed), noise=0.0))
                rec(tcs.read(field, np.random.default_rng(seed), noise=0.5))
        except (IndexError, ValueError) as e:
            out.append(type(e).__name__)
    return len(caught)


if __name__ == "__main__":
    report(scenario, 400)
