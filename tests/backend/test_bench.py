"""The stream benchmark's mechanics on the fast stand-in loop (``furnace-twin bench`` runs it on the
real loop and reports the figures): every key measured, and within the bounds any machine obeys."""

from __future__ import annotations

import math

import pytest

import backend.bench as bench
from conftest import fake_factory


class _FakeFactory:
    def radiation(self, cfg):
        return None

    def truth_radiation(self, cfg):
        return None

    def __call__(self, cfg, scenario, *, budget=None):
        return fake_factory(step_cost_s=0.005)(cfg, scenario)


def test_stream_bench_keys_and_targets(monkeypatch, small_cfg) -> None:
    monkeypatch.setattr(bench, "DefaultLoopFactory", _FakeFactory)
    r = bench.stream_bench(small_cfg, realtime_s=3.0, max_speed_sim_s=10.0)
    assert set(r) >= {"stream_fps_min", "stream_latency_p95_ms", "max_speed_rtf_with_clients",
                      "closed_loop_rtf_bare", "max_speed_rtf_ratio"}
    # The targets (>= 10 frames/s, p95 <= 100 ms, >= 50 % of the bare rate) are judged by
    # `furnace-twin bench` on a quiet machine, never by timing assertions here.  What holds on any
    # machine, however loaded, is checked instead:
    assert all(math.isfinite(v) for v in r.values()), r
    t_s = small_cfg.sampling.t_s
    # no more frames per simulated second than samples (a double-counted frame would exceed it)
    assert 0.0 < r["stream_fps_min"] <= 1.0 / t_s + 1e-9
    # the stand-in busy-waits 5 ms per step: at most t_s / 5 ms = 20 simulated s per wall s
    assert 0.0 < r["closed_loop_rtf_bare"] <= t_s / 0.005 * (1 + 1e-6)
    assert 0.0 < r["max_speed_rtf_with_clients"] <= t_s / 0.005 * (1 + 1e-6)
    assert r["stream_latency_p95_ms"] >= 0.0  # a frame cannot arrive before its sample was taken
    assert r["max_speed_rtf_ratio"] == pytest.approx(r["max_speed_rtf_with_clients"] / r["closed_loop_rtf_bare"])
