"""Second look at the fillet mutants written off as equivalent (scripts/mutation_equivalent.toml, issue 23).

Random grids (2-30 x 2-20 cells, sizes in um..km, the default 26 x 17 grid with centres on the edges) and
fields in several types (float64, float32, int, lists, batches, flat and (N_y, N_x)), references as Python
floats, ints, float32 scalars and arrays; prints a digest of every weights / mask / mean / sup / spread
result (values and dtypes) and the number of warnings.  Run it inside mutmut's ``mutants/`` folder, once for
the original and once per mutant (as scripts/mutation_second_look_glr.py)::

    cd mutants && MUTANT_UNDER_TEST='twin.physics.fillet.xǁFilletǁsup__mutmut_15' \\
        ../.venv/bin/python ../scripts/mutation_second_look_fillet.py
"""

from __future__ import annotations

import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.getcwd())  # mutants/: the mutated twin with its trampolines
from mutation_second_look import out, rec, report  # noqa: E402  (the shared record, scripts/mutation_second_look.py)

from twin.physics.fillet import Fillet  # noqa: E402


def scenario(seed: int) -> int:
    rng = np.random.default_rng(seed)
    if seed % 5 == 0:
        nx, ny, L, W = 26, 17, 0.52, 0.34
    else:
        nx, ny = int(rng.integers(2, 31)), int(rng.integers(2, 21))
        L, W = rng.uniform(0.05, 2.0, 2) * 10.0 ** rng.integers(-6, 7)
    x, y = (np.arange(nx) + 0.5) * L / nx, (np.arange(ny) + 0.5) * W / ny
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        f = Fillet.on_grid(x, y, L, W)
        rec(f.weights)
        rec(f.mask)
        F = rng.uniform(-1e3, 2e3, (3, ny, nx))
        fields = [F[0], F[:2], F[0].ravel(), F.reshape(3, -1), F[0].astype(np.float32), np.rint(F[0]).astype(int),
                  F[0].tolist(), np.rint(F[0]).astype(np.int16)]
        refs = [812.5, 900, np.float32(700.25), np.array(650.0), np.array([600.0, 700.0]), np.array([1, 2, 3])]
        for field in fields:
            rec(f.mean(field))
            rec(f.spread(field))
            for ref in refs:
                try:
                    rec(f.sup(field, ref))
                except ValueError as e:  # a batch of references that does not fit the field's batch
                    out.append(type(e).__name__)
    return len(caught)


if __name__ == "__main__":
    report(scenario, 200)
