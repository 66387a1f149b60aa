"""Readings grouped into samples by the furnace's source timestamps (twin.furnace.opcua.samples): the run
clock starts at an anchor, jitter stays in its sample, a late sample is missing at its deadline, late
readings are dropped, the deadline follows the arrivals (clock offset, drift), and a waiting reader wakes
as soon as its sample is complete."""

from __future__ import annotations

import threading
import time

import pytest

from twin.furnace.opcua.samples import SampleBuffer

T_S = 0.1


class Clock:
    def __init__(self, t: float) -> None:
        self.t = t

    def __call__(self) -> float:
        return self.t


def publish(buf: SampleBuffer, k: int, *, src0: float = 5000.0, arrival0: float = 10.0, jitter: float = 0.0,
            delay: float = 0.003, channels: tuple[int, ...] = (0, 1), value: float | None = None) -> None:
    """Sample k of a furnace whose clock reads src0 at the emulator's start (another machine's clock)."""
    for ch in channels:
        buf.add(ch, 300.0 + k if value is None else value, True, src0 + k * T_S + jitter,
                arrival0 + k * T_S + jitter + delay)


def anchored(delay: float = 0.003) -> SampleBuffer:
    buf = SampleBuffer(T_S, 2, late_s=0.05)
    for k in range(3):
        publish(buf, k, delay=delay)
    r0 = buf.anchor(0.0, now=10.0 + 2 * T_S + delay)
    assert r0 is not None and r0.source_s == pytest.approx(5000.2)
    return buf


def test_anchor_makes_the_newest_sample_t0_and_later_ones_follow() -> None:
    buf = anchored()
    assert [r.value for r in buf.take(0, now=Clock(10.21))] == [302.0, 302.0]
    for k in range(3, 8):
        publish(buf, k, jitter=0.02 * (-1) ** k)  # +-20 ms jitter of the furnace's sampling stays in its sample
        j = k - 2
        assert [r.value for r in buf.take(j, now=Clock(10.0 + k * T_S + 0.03))] == [300.0 + k] * 2


def test_a_late_sample_is_missing_at_its_deadline_and_dropped_when_it_comes() -> None:
    buf = anchored()
    buf.take(0, now=Clock(10.21))
    publish(buf, 3, channels=(0,))  # channel 1 of sample 1 does not come in time
    clock = Clock(10.3 + 0.003 + 0.049)  # due at 10.303, deadline 50 ms later
    t0 = time.monotonic()
    waiting = threading.Thread(target=lambda: time.sleep(0.05) or setattr(clock, "t", 10.36))
    waiting.start()
    got = buf.take(1, now=clock)
    waiting.join()
    assert got[0] is not None and got[1] is None and time.monotonic() - t0 < 2.0
    publish(buf, 3, channels=(1,))  # ... and arrives afterwards: dropped, not filed into a later sample
    assert buf.dropped_late == 1
    publish(buf, 4)
    assert [r.value for r in buf.take(2, now=Clock(10.41))] == [304.0, 304.0]


def test_deadline_follows_the_arrivals_not_the_clocks() -> None:
    """The furnace's clock is 5000 s off ours and the path takes 3 ms: sample j is due 3 ms after it is taken;
    a slower path (20 ms) moves the deadline only if it is the smallest delay seen recently."""
    buf = anchored(delay=0.003)
    assert buf.due(5) == pytest.approx(10.2 + 0.003 + 5 * T_S)
    slow = anchored(delay=0.020)
    assert slow.due(5) == pytest.approx(10.2 + 0.020 + 5 * T_S)


def test_a_reader_wakes_when_its_sample_is_complete() -> None:
    buf = anchored()
    buf.take(0, now=Clock(10.21))
    # real clock from here on: sample 1 due "now", deadline in 50 ms; it arrives after 20 ms
    got: list = []
    start = time.monotonic()

    def reader() -> None:
        got.append(buf.take(1))
        got.append(time.monotonic() - start)

    t = threading.Thread(target=reader)
    now = time.monotonic()
    # shift the learnt delay so that sample 1 is due 0.5 s from now: the reader must not give up early
    buf._delays.clear()
    buf._delays.append(now + 0.5 - T_S)
    t.start()
    time.sleep(0.02)
    publish(buf, 3, arrival0=now - 3 * T_S)
    t.join(timeout=5)
    assert got and all(r is not None for r in got[0])
    assert got[1] < 0.4, "the reader waited for the deadline instead of waking on the sample"


def test_a_dead_first_channel_does_not_stop_the_run_clock() -> None:
    buf = SampleBuffer(T_S, 2, late_s=0.05)
    for k in range(3):
        publish(buf, k, channels=(1,))  # TC1 never reports
    assert buf.anchor(0.0, now=10.21) is not None
    publish(buf, 3, channels=(1,))
    got = buf.take(1, now=Clock(10.36))
    assert got[0] is None and got[1] is not None and got[1].value == 303.0



@pytest.mark.parametrize("relearn", [True, False])
def test_a_new_connection_is_on_time_from_its_first_reading(relearn: bool) -> None:
    """A reconnection subscribes anew, and its readings wait for the server's publishing cycle in another phase:
    here 0.08 s after the sample instead of 0.003 s (open62541 publishes every 100 ms; late_s is 0.05 s).  With
    the buffer told (``relearn``, as the OPC UA furnace does at the first reading of a new connection) each
    sample's deadline is after its readings' arrival at once; without it the old delays in the window (100
    readings: 2 s at a furnace's five channels) put the deadline before the arrival, so every sample of those
    2 s was missing: the o6 restart test found readings used again 2.5 s after the link returned."""
    buf = anchored()
    for j in range(1, 40):  # the first connection, 4 s
        publish(buf, j + 2)
        assert None not in buf.take(j, now=Clock(10.0 + (j + 2) * T_S + 0.003))
    if relearn:
        buf.relearn()
    on_time = []
    for j in range(40, 70):  # the second connection: later in each period
        publish(buf, j + 2, delay=0.08)
        on_time.append(10.0 + (j + 2) * T_S + 0.08 <= buf.due(j) + buf.late_s)
        buf.take(j, now=Clock(10.0 + (j + 2) * T_S + 0.08))
    if relearn:
        assert all(on_time)
    else:  # late while any of the first connection's delays is in the window (100 readings: 50 samples here)
        assert not any(on_time)
