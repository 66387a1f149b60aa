"""The stream benchmark's mechanics on the fast stand-in loop (``furnace-twin bench`` runs it on the
real loop and reports the figures): every key measured, finite, consistent."""

from __future__ import annotations

import math

import pytest

import backend.bench as bench
from conftest import fake_factory


class _FakeFactory:
    def radiation(self, cfg):
        return None

    def __call__(self, cfg, scenario, *, budget=None):
        return fake_factory(step_cost_s=0.005)(cfg, scenario)


def test_stream_bench_keys_and_targets(monkeypatch, small_cfg) -> None:
    monkeypatch.setattr(bench, "DefaultLoopFactory", _FakeFactory)
    r = bench.stream_bench(small_cfg, realtime_s=3.0, max_speed_sim_s=10.0)
    assert set(r) >= {"stream_fps_min", "stream_latency_p95_ms", "max_speed_rtf_with_clients",
                      "closed_loop_rtf_bare", "max_speed_rtf_ratio"}
    # Mechanics only: the figures are measured and finite.  Their targets (>= 10 frames/s,
    # p95 <= 100 ms, >= 50 % of the bare rate) are judged by `furnace-twin bench` on a quiet
    # machine, never by timing assertions in the suite (a loaded CI box would make them flaky).
    assert all(math.isfinite(v) and v > 0 for v in r.values()), r
    assert r["max_speed_rtf_ratio"] == pytest.approx(r["max_speed_rtf_with_clients"] / r["closed_loop_rtf_bare"])
