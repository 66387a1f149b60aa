"""Helpers of the OPC UA tests: an emulator in a subprocess (``furnace-twin emulate``) or in this process
(a thread with its own event loop), a small-config TOML file, free ports, a synchronous peek client, the
dashboard's app with OPC UA settings and waiting for a run's status."""

from __future__ import annotations

import asyncio
import contextlib
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
TEST_CACHE = REPO / ".cache" / "test-radiation"


def small_config_file(folder: Path) -> Path:
    """small_config() as a furnace file (the emulator subprocess and the CLI take --config FILE)."""
    from twin.config import load_config, small_config, small_config_toml

    path = folder / "small_furnace.toml"
    path.write_text(small_config_toml())
    assert load_config(path).digest() == small_config().digest()
    return path


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def endpoint(port: int) -> str:
    return f"opc.tcp://127.0.0.1:{port}/furnace-twin/"


def wait_listening(port: int, timeout: float, proc: subprocess.Popen[bytes] | None = None,
                   log: Path | None = None) -> None:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if proc is not None and proc.poll() is not None:
            raise AssertionError(f"the emulator exited ({proc.returncode}):\n{log.read_text() if log else ''}")
        with socket.socket() as s:
            if s.connect_ex(("127.0.0.1", port)) == 0:
                return
        time.sleep(0.05)
    raise AssertionError(f"nothing listens on port {port} after {timeout} s:\n{log.read_text() if log else ''}")


def child_env(**extra: str) -> dict[str, str]:
    env = {**os.environ, "FURNACE_TWIN_CACHE": str(TEST_CACHE), "OPENBLAS_NUM_THREADS": "1", **extra}
    return env


@dataclass
class EmulatorProcess:
    url: str
    port: int
    proc: subprocess.Popen[bytes]
    log: Path
    stats: Path

    def kill(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)


@contextlib.contextmanager
def emulator_process(folder: Path, *args: str, port: int | None = None, env: dict[str, str] | None = None,
                     timeout: float = 90.0) -> Iterator[EmulatorProcess]:
    """``furnace-twin --config small emulate`` on a free loopback port; stopped (SIGTERM, then SIGKILL) after."""
    folder.mkdir(parents=True, exist_ok=True)
    port = port or free_port()
    log, stats = folder / f"emulator-{port}.log", folder / f"emulator-{port}.json"
    cmd = [sys.executable, "-m", "furnace_twin.cli", "--config", str(small_config_file(folder)), "emulate",
           "--endpoint", endpoint(port), "--data-dir", str(folder / "emulator-data"), "--stats", str(stats), *args]
    with open(log, "wb") as out:
        proc = subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT, env=env or child_env(), cwd=folder)
    try:
        wait_listening(port, timeout, proc, log)
        yield EmulatorProcess(endpoint(port), port, proc, log, stats)
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            try:
                proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=10)


class InProcessEmulator:
    """A :class:`FurnaceEmulator` on a thread with its own event loop (for tests that hand it a furnace)."""

    def __init__(self, emulator: Any) -> None:
        self.emulator = emulator
        self.loop = asyncio.new_event_loop()
        self._stop: asyncio.Event | None = None
        self._thread = threading.Thread(target=self._main, daemon=True, name="test-emulator")
        self._error: BaseException | None = None

    def _main(self) -> None:
        asyncio.set_event_loop(self.loop)

        async def serve() -> None:
            self._stop = asyncio.Event()
            await self.emulator.serve(self._stop)

        try:
            self.loop.run_until_complete(serve())
        except BaseException as exc:  # reported by __exit__
            self._error = exc

    def __enter__(self) -> InProcessEmulator:
        self._thread.start()
        end = time.monotonic() + 30
        while not (self.emulator.ready.is_set() or self._error or time.monotonic() > end):
            time.sleep(0.02)
        if self._error:
            raise self._error
        assert self.emulator.ready.is_set(), "the emulator did not start"
        return self

    def call(self, coro: Any, timeout: float = 10.0) -> Any:
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def __exit__(self, *exc: Any) -> None:
        if self._stop is not None:
            self.loop.call_soon_threadsafe(self._stop.set)
        self._thread.join(timeout=15)
        if self._error:
            raise self._error


class Peek:
    """A synchronous OPC UA client for looking at an emulator from a test (asyncua.sync)."""

    def __init__(self, url: str) -> None:
        from asyncua.sync import Client

        self.client = Client(url, timeout=5)
        self.client.connect()
        furnace = next(ch for ch in self.client.nodes.objects.get_children()
                       if ch.read_browse_name().Name == "Furnace")
        self.furnace = furnace
        self.nodes: dict[str, Any] = {}
        for ch in furnace.get_children():
            name = ch.read_browse_name().Name
            self.nodes[name] = ch
            if name == "LampGroups":
                for g in ch.get_children():
                    self.nodes[g.read_browse_name().Name] = g

    def value(self, name: str) -> Any:
        return self.nodes[name].read_value()

    def data_value(self, name: str) -> Any:
        return self.nodes[name].read_data_value()

    def close(self) -> None:
        with contextlib.suppress(Exception):
            self.client.disconnect()


class TcpProxy:
    """A loopback TCP relay on its own thread: ``cut()`` drops every connection (a network blip), ``refuse``
    makes it turn new ones away, ``close()`` stops it."""

    def __init__(self, target_port: int) -> None:
        self.target_port = target_port
        self.port = free_port()
        self.refuse = False
        self.loop = asyncio.new_event_loop()
        self._writers: set[asyncio.StreamWriter] = set()
        self._server: asyncio.base_events.Server | None = None
        started = threading.Event()

        def main() -> None:
            asyncio.set_event_loop(self.loop)
            self._server = self.loop.run_until_complete(asyncio.start_server(self._client, "127.0.0.1", self.port))
            started.set()
            self.loop.run_forever()

        self._thread = threading.Thread(target=main, daemon=True, name="test-proxy")
        self._thread.start()
        started.wait(10)

    async def _pipe(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        try:
            while data := await reader.read(65536):
                writer.write(data)
                await writer.drain()
        except (ConnectionError, OSError):
            pass
        finally:
            writer.close()

    async def _client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        if self.refuse:
            writer.close()
            return
        up_reader, up_writer = await asyncio.open_connection("127.0.0.1", self.target_port)
        self._writers |= {writer, up_writer}
        await asyncio.gather(self._pipe(reader, up_writer), self._pipe(up_reader, writer))

    def cut(self) -> None:
        async def cut() -> None:
            for w in list(self._writers):
                w.transport.abort()
            self._writers.clear()

        asyncio.run_coroutine_threadsafe(cut(), self.loop).result(5)

    def close(self) -> None:
        if not self._thread.is_alive():
            return
        self.refuse = True
        self.cut()

        async def stop() -> None:
            if self._server is not None:
                self._server.close()

        asyncio.run_coroutine_threadsafe(stop(), self.loop).result(5)
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(5)


def twin_app(tmp_path: Path, cfg: Any, **opcua: Any) -> Any:
    """The dashboard's app on ``cfg`` (a TestClient; use it as a context manager), OPC UA links retried 2 s."""
    from fastapi.testclient import TestClient

    from backend.app import create_app
    from backend.core.settings import Settings
    from twin.furnace.opcua.options import OpcUaOptions

    settings = Settings(data_dir=tmp_path / "data", flush_interval_s=0.5,
                        opcua=OpcUaOptions(**{"reconnect_s": 2.0, "connect_timeout_s": 10.0, **opcua}))
    return TestClient(create_app(settings, cfg), base_url="http://127.0.0.1")


def wait_status(c: Any, run_id: str, statuses: set[str], timeout: float) -> dict[str, Any]:
    """``GET /api/runs/{id}`` until its status is one of ``statuses``."""
    end = time.monotonic() + timeout
    body: dict[str, Any] = {}
    while time.monotonic() < end:
        body = c.get(f"/api/runs/{run_id}").json()
        if body["status"] in statuses:
            return body
        time.sleep(0.1)
    raise AssertionError(f"run {run_id} never reached {statuses}: {body.get('status')} {body.get('error')}")


def run_over_opcua(tmp_path: Path, cfg: Any, scenario: dict[str, Any], *emulate_args: str,
                   timeout: float = 180.0) -> tuple[dict[str, Any], Any, dict[str, Any]]:
    """``scenario`` run through the dashboard's API against ``furnace-twin emulate`` (its furnace: the same
    scenario's, with ``emulate_args``), to its end: (metrics, timeseries.npz, the emulator's stats)."""
    import io
    import json

    import numpy as np

    (tmp_path / "plant.json").write_text(json.dumps(scenario))
    with emulator_process(tmp_path, "--scenario", str(tmp_path / "plant.json"), *emulate_args) as emu, \
            twin_app(tmp_path, cfg) as c:
        r = c.post("/api/runs", json={**scenario, "plant": {"kind": "opcua", "endpoint": emu.url}})
        assert r.status_code == 201, r.text
        run_id = r.json()["id"]
        body = wait_status(c, run_id, {"finished", "error", "plant_lost"}, timeout=timeout)
        assert body["status"] == "finished", body["error"]
        metrics = c.get(f"/api/runs/{run_id}/metrics").json()
        npz = np.load(io.BytesIO(c.get(f"/api/runs/{run_id}/timeseries").content))
    return metrics, npz, json.loads(emu.stats.read_text())

