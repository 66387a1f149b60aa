"""The stream and memory benchmark's mechanics (``furnace-twin bench`` runs it with 20 clients, 2 runs at
speed max and a 1 h run, and reports the figures): a real server process on small_config, every key
measured, finite and consistent."""

from __future__ import annotations

import math

import pytest

import benchmarks.stream as bench
from twin.config import small_config


def test_stream_bench_keys() -> None:
    # the max-speed window is the whole 20 s run: a client gets about 20 frames a second of wall time and attaches
    # after the run has started, so a 5 s window of the small furnace at speed max held 2 frames on a quiet machine
    # (the first at t = 1.6 s) and fewer than 2 (no speed: NaN) once in a loaded full-suite run; the whole run held 9
    r = bench.stream_bench(small_config(), n_clients=3, client_fps=20.0, load_s=3.0, background_runs=1, long_sim_s=20.0,
                           baseline_sim_s=5.0, bare_sim_s=20.0)
    assert set(r) >= {"stream_clients", "stream_fps_min", "stream_fps_min_wall", "stream_latency_p95_ms",
                      "stream_latency_max_ms", "background_rtf_min", "rss_growth_mb", "rss_baseline_mb",
                      "rss_peak_mb", "long_run_rtf", "max_speed_rtf_with_clients", "closed_loop_rtf_bare",
                      "max_speed_rtf_ratio"}
    # Mechanics only: the figures are measured and finite.  Their targets (20 clients at 20 frames/s, p95
    # <= 50 ms, growth < 50 MB) are judged by `furnace-twin bench` on a quiet machine, never by timing
    # assertions in the suite (a loaded CI box would make them flaky).
    assert all(math.isfinite(v) for v in r.values()), r
    assert r["stream_clients"] == 3 and r["stream_fps_min"] > 0 and r["background_rtf_min"] > 0
    assert r["rss_peak_mb"] >= r["rss_baseline_mb"] > 50  # a server with numpy and casadi loaded
    assert r["rss_growth_mb"] == pytest.approx(r["rss_peak_mb"] - r["rss_baseline_mb"])
    assert r["max_speed_rtf_ratio"] == pytest.approx(r["max_speed_rtf_with_clients"] / r["closed_loop_rtf_bare"])
    # what holds on any machine, however loaded: no more frames per second than the live run makes samples
    # (a double-counted frame would exceed it), and no frame before its sample was taken
    assert r["stream_fps_min"] <= 20.0 + 1e-9 and r["stream_latency_p95_ms"] >= 0.0
