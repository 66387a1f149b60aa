"""Lamp groups at a bound (twin.control.saturation): flags per sample and the run's events."""

from __future__ import annotations

import numpy as np

from twin.control.saturation import MIN_FULL_S, MIN_OFF_S, RELEASE_S, SaturationWatch, bound_flags


def _events(watch: SaturationWatch, t_s: float, u2: list[float]) -> list[tuple[float, str, str]]:
    out = []
    for k, v in enumerate(u2):
        out += [(round(e.t, 6), e.level, e.text) for e in watch.update(k * t_s, [0.5, v])]
    return out


def test_flags_mark_full_power_and_off() -> None:
    u = np.array([[1.0, 0.0, 0.5], [0.9995, 0.0004, 0.002]])
    assert bound_flags(u).tolist() == [[1, -1, 0], [1, -1, 0]]


def test_short_clips_stay_quiet_long_spells_are_reported_once_with_their_start() -> None:
    t_s = 0.1
    watch = SaturationWatch(("T1h", "T2v"), t_s)
    short = [1.0] * int(MIN_FULL_S / t_s - 2) + [0.5] * 30  # 0.8 s at full power: feedback action
    assert _events(watch, t_s, short) == []
    watch = SaturationWatch(("T1h", "T2v"), t_s)
    # 3 s at full power with a 0.3 s dip in the middle (shorter than RELEASE_S: one spell), then 2 s below
    u = [0.5] * 5 + [1.0] * 15 + [0.8] * 3 + [1.0] * 12 + [0.7] * 20
    ev = _events(watch, t_s, u)
    assert len(ev) == 2
    (t_on, level_on, on), (t_off, level_off, off) = ev
    assert level_on == "warn" and "T2v at full power" in on and "since t = 0.5 s" in on
    assert t_on == 0.5 + MIN_FULL_S
    assert level_off == "info" and "since t = 3.5 s" in off and "after 3.0 s" in off
    assert t_off == round(3.4 + RELEASE_S, 6)  # the last sample at u_max was 3.4 s


def test_a_group_idling_at_zero_is_one_spell_reported_after_min_off() -> None:
    t_s = 0.1
    watch = SaturationWatch(("T1h", "T3h"), t_s)
    rng = np.random.default_rng(0)
    u = [0.0 if rng.random() < 0.8 else 0.01 for _ in range(200)]  # touches 0 four times in five, 20 s
    ev = _events(watch, t_s, u)
    assert len(ev) == 1 and "T3h off (0 %)" in ev[0][2] and ev[0][0] >= MIN_OFF_S - 1e-9
    assert ev[0][1] == "info"  # off is reported, full power warned


def test_groups_alike_in_one_sample_share_one_event() -> None:
    """At a run's start every group is off while the slow start of the reference needs no heat: one event."""
    watch = SaturationWatch(("T1h", "T2h", "T2v"), 0.1)
    events = []
    for k in range(100):  # 10 s: all off for 6 s, then T1h and T2h on, T2v still off
        u = [0.0, 0.0, 0.0] if k < 60 else [0.3, 0.3, 0.0]
        events += [e.text for e in watch.update(0.1 * k, u)]
    assert events == ["T1h, T2h, T2v off (0 %) since t = 0.0 s: no headroom left to cool",
                      "T1h, T2h on again since t = 6.0 s, after 6.0 s"]
