"""``furnace-twin simulate``: argument errors exit 2 with a message; a short run writes its files."""

from __future__ import annotations

import json
from argparse import Namespace

import numpy as np
import pytest

from furnace_twin.cli import main
from twin.config import small_config
from twin.experiments.simulate import SimulateArgumentError, load_schedule, parse_powers, simulate_command


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["--powers", "1.5"], "[0, 1]"),
        (["--powers", "0.1,0.2"], "1 or 6 values"),
        (["--powers", "abc"], "expected numbers"),
        (["--duration", "-3"], "--duration"),
        (["--oscillate", "--amplitude", "0.2"], "amplitude"),
        (["--oscillate", "--period", "0.1"], "period"),
        (["--schedule", "/nonexistent/schedule.json"], "cannot read"),
    ],
)
def test_bad_arguments_exit_2_with_a_message(argv, needle, capsys, tmp_path):
    code = main(["simulate", "--out", str(tmp_path / "o"), *argv])
    err = capsys.readouterr().err
    assert code == 2
    assert needle in err
    assert "Traceback" not in err


def test_schedule_validation(tmp_path):
    p = tmp_path / "s.json"
    p.write_text(json.dumps([[0, [0.5] * 6], [10, [0.2] * 6]]))
    t, u = load_schedule(str(p), 6)
    np.testing.assert_array_equal(t, [0, 10])
    assert u.shape == (2, 6)
    p.write_text(json.dumps([[5, [0.5] * 6], [1, [0.2] * 6]]))
    with pytest.raises(SimulateArgumentError, match="increasing"):
        load_schedule(str(p), 6)
    p.write_text(json.dumps([[0, [0.5] * 5]]))
    with pytest.raises(SimulateArgumentError, match="6"):
        load_schedule(str(p), 6)
    np.testing.assert_array_equal(parse_powers("0.3", 6), np.full(6, 0.3))


def test_short_run_writes_timeseries_and_figures(tmp_path, radiation_cache):
    cfg = small_config()
    sched = tmp_path / "sched.json"
    sched.write_text(json.dumps([[1.0, [0.8, 0.8, 0.8, 0.8, 0.4, 0.4]]]))
    args = Namespace(
        powers="0.5",
        schedule=str(sched),
        duration=3.0,
        oscillate=True,
        amplitude=0.048,
        period=18.0,
        tc4=(0.5, 0.5),
        seed=3,
        out=str(tmp_path / "run"),
    )
    assert simulate_command(cfg, args) == 0
    ts = np.load(tmp_path / "run" / "timeseries.npz")
    n = int(round(3.0 / cfg.sampling.t_s)) + 1
    assert ts["t"].shape == (n,)
    assert ts["u"].shape == (n, 6) and ts["tc"].shape == (n, 4)
    assert ts["field"].shape[1:] == (cfg.specimen.ny, cfg.specimen.nx)
    assert ts["field"].shape[0] == 4  # t = 0, 1, 2, 3 s
    # the schedule switches at t = 1 s (zero-order hold): before it --powers applies
    np.testing.assert_array_equal(ts["u"][0], np.full(6, 0.5))
    np.testing.assert_array_equal(ts["u"][-1], [0.8, 0.8, 0.8, 0.8, 0.4, 0.4])
    np.testing.assert_allclose(ts["eta"], 0.048 * np.sin(2 * np.pi * ts["t"] / 18.0), atol=1e-15)
    # the lamps heat the cold plate
    assert ts["fillet_mean"][-1] > ts["fillet_mean"][0] + 5.0
    # the honest truth by default: the TCs trail the heating plate by tau dT/dt (first-order lag) and read a
    # seeded bias (within the class 1 band, 1.5 K here) plus noise of sigma = cfg.sensors.noise (1 K)
    tau = cfg.truth.thermocouples.time_constant
    rate = np.gradient(ts["tc_true"], cfg.sampling.t_s, axis=0)
    settled = ts["t"] >= 1.0 + 4 * tau  # the schedule switches at 1 s
    resid = (ts["tc"] - ts["tc_true"] + tau * rate)[settled]
    assert np.all(rate[settled] > 5.0)  # K/s: a lag of ~1 K or more, well visible
    assert 0.5 * cfg.sensors.noise < (resid - resid.mean(axis=0)).std() < 2.0 * cfg.sensors.noise
    assert np.all(np.abs(resid.mean(axis=0)) < 1.5 + 4 * cfg.sensors.noise / np.sqrt(settled.sum()) + 0.3)
    for name in ("field.png", "tc.png"):
        assert (tmp_path / "run" / name).stat().st_size > 10_000
    # the model's plant with ideal sensors (--truth shared): readings are the plate plus noise alone, and the
    # plate heats faster (no lamp lag, no -10 % lamp efficiency)
    args.truth, args.out = "shared", str(tmp_path / "shared")
    assert simulate_command(cfg, args) == 0
    shared = np.load(tmp_path / "shared" / "timeseries.npz")
    resid = (shared["tc"] - shared["tc_true"]).ravel()
    assert 0.5 * cfg.sensors.noise < resid.std() < 2.0 * cfg.sensors.noise and abs(resid.mean()) < 0.5
    assert shared["fillet_mean"][-1] > ts["fillet_mean"][-1] + 0.5
