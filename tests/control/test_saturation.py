"""Lamp groups at a bound (twin.control.saturation): flags per sample, and one event per spell that matters
(issue 27: 14 of 24 events were lamp groups on / off, e.g. every group "off ... no headroom left to cool" at the
start of a heat-up, where it does not matter)."""

from __future__ import annotations

import numpy as np

from twin.control.saturation import MATTERS_K, MIN_FULL_S, MIN_OFF_S, RELEASE_S, SaturationWatch, bound_flags


def _events(watch: SaturationWatch, t_s: float, u2: list[float], error: float | list[float] | None = None,
            flush: bool = False) -> list[tuple[float, str, str]]:
    out = []
    for k, v in enumerate(u2):
        err = error[k] if isinstance(error, list) else error
        out += [(round(e.t, 6), e.level, e.text) for e in watch.update(k * t_s, [0.5, v], err)]
    if flush:
        out += [(round(e.t, 6), e.level, e.text) for e in watch.flush(len(u2) * t_s)]
    return out


def test_flags_mark_full_power_and_off() -> None:
    u = np.array([[1.0, 0.0, 0.5], [0.9995, 0.0004, 0.002]])
    assert bound_flags(u).tolist() == [[1, -1, 0], [1, -1, 0]]


def test_short_clips_stay_quiet_a_long_spell_is_one_event_when_it_ends() -> None:
    t_s = 0.1
    watch = SaturationWatch(("T1h", "T2v"), t_s)
    short = [1.0] * int(MIN_FULL_S / t_s - 2) + [0.5] * 30  # 0.8 s at full power: feedback action
    assert _events(watch, t_s, short, error=10.0) == []
    watch = SaturationWatch(("T1h", "T2v"), t_s)
    # 3 s at full power with a 0.3 s dip in the middle (shorter than RELEASE_S: one spell), then 2 s below;
    # the mean falls behind the reference up to 6 K (at 2.0 s) during the spell
    u = [0.5] * 5 + [1.0] * 15 + [0.8] * 3 + [1.0] * 12 + [0.7] * 20
    err = [0.0] * 5 + [0.4 * k for k in range(15)] + [0.0] * 3 + [3.0] * 12 + [0.0] * 20
    ev = _events(watch, t_s, u, err)
    assert len(ev) == 1
    t, level, text = ev[0]
    assert level == "warn"
    assert text == "T2v at full power from t = 0.5 s for 3.0 s: the fillet mean fell up to 5.6 K behind the reference"
    assert t == round(3.4 + RELEASE_S, 6)  # the last sample at u_max was 3.4 s


def test_lamps_off_while_the_mean_is_below_the_reference_stay_quiet() -> None:
    """The start of a heat-up: the optimum keeps groups off while the reference still starts slowly."""
    t_s = 0.1
    watch = SaturationWatch(("T1h", "T3h"), t_s)
    rng = np.random.default_rng(0)
    u = [0.0 if rng.random() < 0.8 else 0.01 for _ in range(200)]  # touches 0 four times in five, 20 s
    assert _events(watch, t_s, u, error=3.0, flush=True) == []  # behind the reference: off does not matter
    # the same spell with the mean 4 K above the reference: the lamps cannot cool it; one event, at the end
    watch = SaturationWatch(("T1h", "T3h"), t_s)
    ev = _events(watch, t_s, u, error=-4.0, flush=True)
    assert len(ev) == 1 and ev[0][2].startswith("T3h off from t = ")
    assert "stayed up to 4.0 K above the reference" in ev[0][2] and ev[0][0] == 20.0


def test_a_spell_within_the_tolerance_does_not_matter() -> None:
    t_s = 0.1
    u = [1.0] * 50 + [0.5] * 20
    assert _events(SaturationWatch(("T1h", "T2v"), t_s), t_s, u, error=MATTERS_K - 0.5) == []
    assert len(_events(SaturationWatch(("T1h", "T2v"), t_s), t_s, u, error=MATTERS_K + 0.5)) == 1
    # without the error (a caller that does not know it) a long spell is reported, with the old words
    ev = _events(SaturationWatch(("T1h", "T2v"), t_s), t_s, u)
    assert ev == [(5.9, "warn", "T2v at full power from t = 0.0 s for 5.0 s: no headroom left to heat")]


def test_groups_alike_share_one_event() -> None:
    watch = SaturationWatch(("T1h", "T2h", "T2v"), 0.1)
    events = []
    for k in range(100):  # 10 s: all at full power for 6 s, 8 K behind, then T1h and T2h below, T2v still full
        u = [1.0, 1.0, 1.0] if k < 60 else [0.7, 0.7, 1.0]
        events += [e.text for e in watch.update(0.1 * k, u, 8.0)]
    events += [e.text for e in watch.flush(10.0)]
    assert events == ["T1h, T2h at full power from t = 0.0 s for 6.0 s: the fillet mean fell up to 8.0 K behind "
                      "the reference",
                      "T2v at full power from t = 0.0 s for 10.0 s: the fillet mean fell up to 8.0 K behind the "
                      "reference"]
    assert MIN_OFF_S > MIN_FULL_S  # off is normal for longer than full power
