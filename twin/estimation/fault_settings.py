"""The fault detector's settings and its decisions (:mod:`twin.estimation.fault_detection`).

:class:`DetectionSettings` holds every threshold and window of the reading and innovation tests in one
place (the measured choices: docs/faults.md); :class:`Detection` is one decision of
:class:`twin.estimation.fault_detection.FaultDetector`.

Example
-------
>>> s = DetectionSettings(llr_threshold=80.0)
>>> s.llr_threshold, s.llr_margin
(80.0, 10.0)
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class DetectionSettings:
    """Thresholds and windows of the tests (module docstring); measured choices in docs/faults.md."""

    dropout_s: float = 0.5  # no usable reading for this long: dropped out
    flat_s: float = 1.0  # the same value for this long: stuck
    flat_tolerance: float = 1e-6  # K; two readings closer than this are "the same value"
    onset_every_s: float = 1.0  # a GLR bank (candidate onset) every this many s
    window_s: float = 20.0  # and each one kept this long (finite memory)
    min_age_s: float = 0.5  # a bank is judged after this long
    llr_threshold: float = 60.0  # log-likelihood ratio to declare a fault
    llr_margin: float = 10.0  # and by how much it must beat the runner-up of the same onset
    min_offset: float = 3.0  # K: smaller offsets are left to the estimate
    min_drift: float = 0.05  # K/s
    min_power_loss: float = 0.2  # of a group's nominal power
    failed_below: float = 0.15  # a group keeping less than this of its power is failed
    gain_slack: float = 0.25  # a group's power is taken between -slack and 1 + slack of nominal (plausible fits)
    common_range: tuple[float, float] = (-0.5, 0.5)  # plausible loss of all groups' power (lamp efficiency)
    capacity_range: tuple[float, float] = (-0.5, 1.0)  # plausible heat capacity deviation (Curie peak ~ +50 %)
    readmit_s: float = 3.0  # a left-out TC reads consistently this long: used again
    # "consistently": |mean normalised innovation| over readmit_s below this, after a dropout or a stuck
    # reading.  Not 1: a TC's own bias (the truth's class-1 tolerance, up to 3.3 K), which the estimate absorbs
    # while it uses the TC, shows once it is left out: after a 10 s TC3 dropout its normalised innovations
    # were 1.3-3.4, about 2 on average (small_config, seeds 0-2)
    readmit_z: float = 3.0
    # the same after an offset or a drift, whose readings were wrong: back within the estimate's own
    # uncertainty (at 3 a TC3 offset by -5 K was used again, and the TC4 error rose from 4.0 to 4.9 K)
    readmit_z_biased: float = 1.0
    block_s: float = 1.0  # innovation inflation (FaultDetector._track_inflation): block length
    inflation_lag_s: float = 5.0  # blocks of the last this many s are not used for it
    inflation_history_s: float = 60.0  # blocks used, before the lag
    warm_up_s: float = 20.0  # no innovation test decides before the inflation has this much history


@dataclass(frozen=True)
class Detection:
    """One decision of the detector."""

    t: float  # s, when declared
    onset: float  # s, estimated start
    target: str  # "TC2" or a lamp group name
    kind: str  # dropout, stuck, offset, drift, failed, derate, restored, readmitted
    value: float | None  # offset K, drift K/s, derate: fraction of the nominal power kept
    text: str
