"""``furnace-twin bench --hil``: hardware-in-the-loop timing on loopback, the emulator in its own process.

``furnace-twin emulate`` (the same furnace config, its specimen loaded when the twin starts) serves the
simulated furnace on a free loopback port; this process runs the closed loop against it over OPC UA for
``duration`` seconds of real time (the default reference, 1100 K in 120 s).  Reported, each as p50 / p99 /
max in ms:

* ``emulator_period_ms``: time between the emulator's TC readings (its sample clock);
* ``twin_period_ms``: time between the twin's lamp writes as they reach the emulator (the loop's period,
  paced by the furnace's samples);
* ``sample_jitter_ms``: abs(period - t_s) of the twin's writes, the sample-period jitter;
* ``tc_to_lamp_ms``: from the emulator taking a TC reading to the lamp write that answers it (plant step
  and publish in the emulator, the link both ways, the twin's estimator and controller);
* ``step_ms``: the twin's estimator + controller per sample (no waiting);
* ``late_samples`` (the twin's count) and ``unanswered_readings`` (the emulator's), and the 1-minute load
  average before and after, since timing figures mean little on a loaded machine.

Repeat on a quiet machine: ``furnace-twin bench --hil --duration 300 --json``.
"""

from __future__ import annotations

import json
import logging
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import FurnaceConfig

log = logging.getLogger(__name__)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _wait_listening(port: int, proc: subprocess.Popen[bytes], timeout: float) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc.poll() is not None:
            raise RuntimeError(f"the emulator exited with status {proc.returncode}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.1)
    raise RuntimeError(f"the emulator did not listen on port {port} within {timeout:g} s")


def hil_figures(cfg: FurnaceConfig, config_arg: str | None, duration: float = 300.0) -> dict[str, Any]:
    """Run the emulator and a closed loop over OPC UA for ``duration`` s; the timing figures."""
    from twin.furnace.emulator.timing import percentiles_ms
    from twin.furnace.opcua.furnace import OpcUaFurnace
    from twin.furnace.opcua.options import OpcUaOptions
    from twin.radiation import radiation_model
    from twin.runs.loop import ClosedLoop
    from twin.scenario import Scenario

    radiation = radiation_model(cfg)  # before the emulator starts: its own load is then a cache hit
    port = _free_port()
    url = f"opc.tcp://127.0.0.1:{port}/furnace-twin/"
    load_before = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="furnace-twin-hil-") as tmp:
        stats = Path(tmp) / "emulator.json"
        cmd = [sys.executable, "-m", "furnace_twin.cli", *(["--config", config_arg] if config_arg else []), "emulate",
               "--endpoint", url, "--load-on-first-client", "--data-dir", tmp, "--stats", str(stats)]
        emulator = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=open(Path(tmp) / "emulator.log", "wb"))
        try:
            _wait_listening(port, emulator, timeout=300.0)
            scenario = Scenario.model_validate({"duration": duration, "plant": {"kind": "opcua", "endpoint": url}})
            furnace = OpcUaFurnace(cfg, url, options=OpcUaOptions(), cert_dir=Path(tmp) / "twin")
            loop = ClosedLoop(cfg, scenario, radiation, furnace=furnace)
            log.info("hil: closed loop over OPC UA for %.0f s of real time", duration)
            try:
                for _ in loop.run():
                    pass
            finally:
                loop.close()
        finally:
            emulator.send_signal(signal.SIGTERM)
            emulator.wait(timeout=30)
        emu = json.loads(stats.read_text())
    t_s = cfg.sampling.t_s
    load_after = os.getloadavg()[0]
    write_gaps = np.asarray(emu.get("twin_periods_s", []), float)
    return {
        "hil_duration_s": duration,
        "emulator_period_ms": emu["emulator_period_ms"],
        "twin_period_ms": emu["twin_period_ms"],
        "sample_jitter_ms": percentiles_ms(np.abs(write_gaps - t_s)),
        "tc_to_lamp_ms": emu["tc_to_lamp_ms"],
        "step_ms": percentiles_ms(np.asarray(loop.compute_ms[1:]) / 1000.0),
        "late_samples": int(loop.late_samples),
        "unanswered_readings": emu["unanswered_readings"],
        "interlock_trips": emu["interlock_trips"],
        "load_1min_before": round(load_before, 2),
        "load_1min_after": round(load_after, 2),
    }
