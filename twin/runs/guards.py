"""Sanity of a running loop: the estimate and the inputs must stay finite and physical.

An estimator that diverges (too much TC noise for its model, a wrong model, a broken sensor it
trusts) does not announce it: its estimate runs off to -1.5e8 K while the controller drives every
lamp group to full power, until a NaN crashes the plant's integrator.  :class:`DivergenceGuard`
checks every sample before its inputs reach the furnace and names the first thing that is wrong:

* every value of the estimate (field, fillet mean, at the TCs) and of the inputs is a finite number;
* the estimated field lies within [``T_min``, ``T_max``]: nothing in the furnace is colder than its
  coldest surrounding (``twin.control.reference.coldest_surrounding``), nothing hotter than the top of
  the material tables the model holds, each widened by :data:`MARGIN_K` plus 10 noise sigmas;
* the readings TC1..TC3 the estimator uses (not those the fault detection left out) do not stay far from
  its estimate there: more than
  :data:`INNOVATION_K` (or 10 noise sigmas, if larger) for :data:`INNOVATION_SAMPLES` samples in a row.

The loop (:class:`twin.runs.loop.ClosedLoop`) then switches the lamps off and raises
:class:`EstimateDiverged`; the run ends with status ``error`` and that reason, its data up to the
last sane sample kept.

Example
-------
>>> from twin.config import small_config
>>> guard = DivergenceGuard.for_furnace(small_config(), tc_noise=1.0)
>>> guard.T_min < 300.0 < 1100.0 < guard.T_max
True
>>> guard.problem(field=np.full((2, 2), -1.5e8), T_mean=-1.5e8, tc=np.full(4, 900.0), tc_hat=np.full(4, 900.0),
...               u=np.ones(6))
'the estimated field reaches -1.5e+08 K, below the 140 K any part of this furnace can have'
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from twin.config import FurnaceConfig

#: K added beyond the physical bounds (estimates overshoot a little, and a loop may start off-range)
MARGIN_K = 150.0
#: |TC_i - estimate at xi_i| (K) that, held for INNOVATION_SAMPLES samples, counts as lost track
INNOVATION_K = 150.0
INNOVATION_SAMPLES = 50  # 5 s at t_s = 0.1 s: longer than any transient of a sane estimate
NOISE_SIGMAS = 10.0
ESTIMATOR_TCS = 3  # TC1..TC3 feed the estimator; TC4 only validates


class EstimateDiverged(RuntimeError):
    """The estimate (or the inputs made from it) left the physical range: the run was stopped, lamps off."""


@dataclass
class DivergenceGuard:
    """Checks one sample at a time (module docstring); keeps the count of far-off innovations."""

    T_min: float
    T_max: float
    innovation_max: float
    innovation_samples: int = INNOVATION_SAMPLES
    _far: int = field(default=0, init=False)

    @classmethod
    def for_furnace(cls, cfg: FurnaceConfig, tc_noise: float) -> DivergenceGuard:
        from twin.control.reference import coldest_surrounding

        widen = MARGIN_K + NOISE_SIGMAS * tc_noise
        return cls(T_min=coldest_surrounding(cfg) - widen, T_max=float(cfg.material.temperatures[-1]) + widen,
                   innovation_max=max(INNOVATION_K, NOISE_SIGMAS * tc_noise))

    def problem(self, *, field: ArrayLike, T_mean: float, tc: ArrayLike, tc_hat: ArrayLike,
                u: ArrayLike) -> str | None:
        """``None`` if the sample is sane, else what is wrong (one sentence)."""
        f = np.asarray(field, float)
        for name, values in (("estimated field", f), ("estimated fillet mean", np.asarray(T_mean, float)),
                             ("estimate at the TCs", np.asarray(tc_hat, float)),
                             ("lamp group powers", np.asarray(u, float))):
            if not np.all(np.isfinite(values)):
                return f"the {name} is not a finite number"
        lo, hi = float(f.min()), float(f.max())
        if lo < self.T_min:
            return f"the estimated field reaches {lo:.5g} K, below the {self.T_min:.0f} K any part of this " \
                   f"furnace can have"
        if hi > self.T_max:
            return f"the estimated field reaches {hi:.5g} K, above the {self.T_max:.0f} K the model covers"
        innov = np.abs(np.asarray(tc, float)[:ESTIMATOR_TCS] - np.asarray(tc_hat, float)[:ESTIMATOR_TCS])
        far = np.isfinite(innov) & (innov > self.innovation_max)
        self._far = self._far + 1 if far.any() else 0
        if self._far >= self.innovation_samples:
            worst = int(np.nanargmax(np.where(np.isfinite(innov), innov, -1.0)))
            return (f"TC{worst + 1} has been more than {self.innovation_max:.0f} K from the estimate for "
                    f"{self._far} samples (now {innov[worst]:.0f} K): the estimate lost track")
        return None

    def check(self, snap: Any, left_out: ArrayLike | None = None) -> str | None:
        """:meth:`problem` of a :class:`twin.runs.record.Snapshot`; TCs in ``left_out`` (bool, TC1..3: the
        fault detection found them faulty and the estimator does not use them) are not compared."""
        tc = np.asarray(snap.tc, float)
        if left_out is not None and np.any(left_out):
            tc = tc.copy()
            tc[:ESTIMATOR_TCS][np.asarray(left_out, bool)] = np.nan
        return self.problem(field=snap.field_hat, T_mean=snap.T_mean_hat, tc=tc, tc_hat=snap.tc_hat, u=snap.u)
