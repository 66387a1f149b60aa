"""A recording of a furnace without truth (a real one over OPC UA) has no true curves or images; one of a
simulation has them (read back with rerun's own CLI)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from backend.storage.recording import RecordingSink
from twin.runs.record import Snapshot


def _snap(j: int, cfg, truth: bool) -> Snapshot:
    s = cfg.specimen
    field = np.full((s.ny, s.nx), 500.0 + j)
    return Snapshot(j=j, t=0.1 * j, eta=0.0, T_ref=500.0, T_mean_hat=500.0 + j, field_hat=field,
                    field_true=field + 1.0 if truth else None, tc=np.full(4, 500.0), tc_hat=np.full(4, 500.0),
                    u=np.full(6, 0.5), u_ff=np.full(6, 0.5), inhomogeneity=1.0,
                    true_mean=501.0 + j if truth else None, true_inhomogeneity=2.0 if truth else None)


def _entities(rrd: Path, home: Path) -> str:
    rerun = Path(__file__).resolve().parents[2] / ".venv" / "bin" / "rerun"
    env = {"HOME": str(home), "XDG_CONFIG_HOME": str(home / "cfg"), "XDG_CACHE_HOME": str(home / "cache"),
           "XDG_DATA_HOME": str(home / "data"), "PATH": "/usr/bin:/bin", "RERUN_ANALYTICS": "0"}
    out = subprocess.run([str(rerun), "rrd", "stats", str(rrd)], capture_output=True, text=True, env=env, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


@pytest.mark.parametrize("truth", [False, True])
def test_true_series_only_with_truth(tmp_path, small_cfg, isolated_home, truth) -> None:
    rrd = tmp_path / "recording.rrd"
    sink = RecordingSink(small_cfg, f"truth-{truth}", rrd, tc_positions=small_cfg.tc_positions(), image_interval=0.1)
    for j in range(5):
        sink.add(_snap(j, small_cfg, truth))
    sink.close()
    stats = _entities(rrd, isolated_home)
    assert "/temperature/T_mean_hat" in stats and "/field/estimated" in stats
    for entity in ("/temperature/true_mean", "/inhomogeneity/true", "/field/true"):
        assert (entity in stats) == truth, entity


@pytest.mark.parametrize("sigma", [False, True])
def test_uncertainty_only_when_the_run_reports_it(tmp_path, small_cfg, isolated_home, sigma) -> None:
    """field/sigma and uncertainty/* (issue 25) are written when the snapshots carry field_sigma, never made up."""
    from dataclasses import replace

    rrd = tmp_path / "recording.rrd"
    sink = RecordingSink(small_cfg, f"sigma-{sigma}", rrd, tc_positions=small_cfg.tc_positions(), image_interval=0.1)
    for j in range(5):
        snap = _snap(j, small_cfg, True)
        if sigma:
            snap = replace(snap, field_sigma=np.full(snap.field_hat.shape, 2.0), sigma_mean=1.0, nis=0.8)
        sink.add(snap)
    sink.close()
    stats = _entities(rrd, isolated_home)
    for entity in ("/field/sigma", "/uncertainty/sigma_mean", "/uncertainty/nis"):
        assert (entity in stats) == sigma, entity
