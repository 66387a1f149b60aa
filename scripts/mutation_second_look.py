"""What every ``scripts/mutation_second_look_<module>.py`` shares (issue 23): the record of results and the digest.

A second look runs random scenarios against the original module and against one mutant (inside mutmut's
``mutants/`` folder, ``MUTANT_UNDER_TEST`` naming the mutant) and prints one line, the digest of every result it
recorded (values, dtypes, shapes) and the number of warnings; a mutant written off as equivalent must print the
original's line.  Each module's script records with :func:`rec` (or appends to :data:`out`) and ends with
:func:`report`.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import sys
from collections.abc import Callable

import numpy as np

#: everything a scenario recorded, in order
out: list[object] = []


def rec(x: object) -> None:
    """Record a result with its dtype and shape (an equal value of another dtype is a different result)."""
    a = np.asarray(x)
    out.append((str(a.dtype), a.shape, a.tobytes()))


def report(scenario: Callable[[int], int], seeds: int) -> None:
    """Run ``scenario(seed)`` (it returns its number of warnings) for each seed and print the mutant's line."""
    n_warnings = sum(scenario(seed) for seed in range(seeds))
    digest = hashlib.sha256(pickle.dumps(out)).hexdigest()[:16]
    sys.stdout.write(f"{os.environ.get('MUTANT_UNDER_TEST') or 'original'} {digest} warnings {n_warnings}\n")
