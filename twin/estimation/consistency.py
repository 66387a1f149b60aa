"""Is the filter's claimed uncertainty true?  NEES, NIS and coverage (Bar-Shalom, Li, Kirubarajan 2001, ch. 5.4).

* NEES of one sample: e^T P^{-1} e with the estimation error e = x_hat - x (n,); for a consistent filter
  it is chi-square with n degrees of freedom, so the mean over N independent runs times N is chi-square
  with N n degrees of freedom: :func:`chi2_interval` gives the two-sided acceptance region.
* The twin's field (the truth lives on the FD cells, not in the FE state) is judged cell by cell:
  :func:`cell_nees` is the mean over the fillet's cells of ((T_hat - T) / sigma)^2 (1 when consistent), and
  :func:`coverage` the share of cells x samples with |T_hat - T| <= k sigma (95.4 % for k = 2 if Gaussian).

Example
-------
>>> import numpy as np
>>> round(nees(np.array([1.0, 2.0]), np.diag([1.0, 4.0])), 6)
2.0
>>> lo, hi = chi2_interval(dof=2, runs=50); round(lo, 3), round(hi, 3)   # Bar-Shalom et al.: [1.5, 2.6]
(1.484, 2.591)
>>> float(coverage(np.array([0.0, 1.0, 3.0]), np.ones(3)))
0.6666666666666666
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

Array = NDArray[np.float64]


def nees(error: ArrayLike, P: ArrayLike) -> float:
    """e^T P^{-1} e (P symmetric positive definite)."""
    e = np.asarray(error, float)
    return float(e @ np.linalg.solve(np.asarray(P, float), e))


def chi2_interval(dof: int, runs: int, probability: float = 0.95) -> tuple[float, float]:
    """Two-sided ``probability`` region of the mean of ``runs`` independent chi-square(dof) values."""
    from scipy.stats import chi2  # here, not at the top: scipy.stats costs 0.6 s to import and a run never asks

    a = (1.0 - probability) / 2.0
    n = dof * runs
    return float(chi2.ppf(a, n) / runs), float(chi2.ppf(1.0 - a, n) / runs)


def coverage(error: ArrayLike, sigma: ArrayLike, k: float = 2.0) -> Any:
    """Share of finite entries with |error| <= k sigma (NaN if none is finite)."""
    e, s = np.asarray(error, float), np.asarray(sigma, float)
    ok = np.isfinite(e) & np.isfinite(s)
    return float(np.mean(np.abs(e[ok]) <= k * s[ok])) if ok.any() else float("nan")


def cell_nees(field_hat: ArrayLike, field_true: ArrayLike, sigma: ArrayLike, mask: ArrayLike) -> Any:
    """Mean over the cells in ``mask`` of ((T_hat - T) / sigma)^2, per sample: (..., N_y, N_x) -> (...)."""
    z = (np.asarray(field_hat, float) - np.asarray(field_true, float)) / np.asarray(sigma, float)
    return np.mean(z[..., np.asarray(mask, bool)] ** 2, axis=-1)
