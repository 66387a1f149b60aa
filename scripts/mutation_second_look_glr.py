"""Second look at the GLR mutants written off as equivalent (scripts/mutation_equivalent.toml, issue 23).

Runs 300 random scenarios of twin.estimation.glr (every kind of hypothesis, missing and untested readings,
S scaled 1e-13..1e13, columns/u/increments of several types, resets) and prints a digest of every table(),
best() and candidate() result and the number of warnings.  Run it inside mutmut's ``mutants/`` folder (after
``bash scripts/mutation.sh twin.estimation.glr``) once for the original and once per mutant; a mutant is
indistinguishable in these scenarios when its digest and warning count equal the original's::

    cd mutants && ../.venv/bin/python ../scripts/mutation_second_look_glr.py
    cd mutants && MUTANT_UNDER_TEST='twin.estimation.glr.xǁSignatureBanksǁtable__mutmut_43' \
        ../.venv/bin/python ../scripts/mutation_second_look_glr.py

FINITE=1 leaves out the non-finite inputs (NaN rows of C, NaN gains, NaN/inf increments).
"""

from __future__ import annotations

import os
import sys
import warnings

import numpy as np

sys.path.insert(0, os.getcwd())  # mutants/: the mutated twin with its trampolines
from twin.estimation.glr import SignatureBanks  # noqa: E402

FIN = int(os.environ.get("FINITE", "0"))
KINDS = ("offset", "drift", "lamp", "common", "capacity")
from mutation_second_look import out, report  # noqa: E402  (the shared record and digest)


def rec(x: object) -> None:
    out.append((str(x.dtype), x.shape, x.tobytes()) if isinstance(x, np.ndarray) else repr(x))


def rec_table(t) -> None:
    if t is None:
        rec(None)
        return
    for f in (t.llr, t.size, t.sigma, t.onsets, t.ages):
        rec(f)


def rec_cand(c) -> None:
    rec(None if c is None else (c.hypothesis, c.onset, c.age, c.size, c.sigma, c.llr, c.runner_up, c.runner_up_llr))


def scenario(seed: int) -> int:
    """One random run; returns the number of warnings it raised."""
    rng = np.random.default_rng(seed)
    n, p, m = (int(v) for v in (rng.integers(1, 6), rng.integers(1, 5), rng.integers(1, 4)))
    kinds = tuple(str(k) for k in rng.choice(KINDS, int(rng.integers(1, 8))))
    cols = [int(rng.integers(0, p)) if k in ("offset", "drift") else int(rng.integers(0, m)) for k in kinds]
    colarg = [tuple(cols), list(cols), np.array(cols, np.int32)][seed % 3]
    banks = SignatureBanks(n, p, kinds, colarg, onset_every=int(rng.integers(1, 5)),
                           window=int(rng.integers(1, 9)), t_s=float(rng.uniform(0.05, 3)))
    scale = 10.0 ** rng.integers(-13, 14) if seed % 7 == 0 else 1.0
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        for j in range(int(rng.integers(1, 25))):
            C = rng.normal(size=(p, n))
            nu = rng.normal(size=p)
            nu[rng.random(p) < 0.2] = np.nan
            M = rng.normal(size=(p, p))
            S = (M @ M.T + 0.1 * np.eye(p)) * scale
            L = rng.normal(size=(n, p)) * 0.3
            L[:, ~np.isfinite(nu)] = 0.0
            if FIN == 0 and seed % 11 == 0 and rng.random() < 0.3:  # a reading without a model row
                r = rng.integers(0, p)
                C[r] = np.nan
                L[:, r] = 0.0 if rng.random() < 0.5 else np.nan
            banks.update(j, C, nu, S, L, rng.random(p) < 0.8)
            rec_table(banks.table())
            for min_age in range(4):
                rec_cand(banks.best(min_age))
            Phi, Gamma, u = rng.normal(size=(n, n)) * 0.4, rng.normal(size=(n, m)), rng.uniform(0, 3, m)
            if seed % 4 == 1:
                u = list(u)
            if seed % 4 == 2:
                u = rng.integers(0, 4, m)
            if seed % 4 == 3:
                u, Gamma = u.astype(np.float32), Gamma.astype(np.float32)
            inc = [None, rng.normal(size=n), list(rng.normal(size=n)), rng.normal(size=n).astype(np.float32),
                   rng.integers(-2, 3, n)][int(rng.integers(0, 5))]
            if FIN == 0 and seed % 13 == 0 and inc is not None and rng.random() < 0.2:
                inc = np.array(inc, float)
                inc[0] = [np.nan, np.inf][int(rng.integers(0, 2))]
            banks.predict(Phi, Gamma, u, inc)
            if rng.random() < 0.05:
                banks.reset()
                rec_table(banks.table())
        tab = banks.table()
        if tab is not None:
            for _ in range(5):
                k, h = int(rng.integers(0, tab.llr.shape[0])), int(rng.integers(0, tab.llr.shape[1]))
                comp = np.where(rng.random(tab.llr.shape) < 0.5, tab.llr, 0.0)
                if rng.random() < 0.3:
                    comp[rng.random(comp.shape) < 0.3] = -np.inf
                rec_cand(tab.candidate(k, h, tab.llr))
                rec_cand(tab.candidate(k, h, comp))
    return len(caught)


if __name__ == "__main__":
    report(scenario, 300)
