"""The hardware-in-the-loop emulator: a simulated furnace served in real time as an OPC UA server.

Every sample time t_s of the wall clock (ticks at fixed times from the start, so lateness does not
accumulate) the emulator

1. checks the interlock (:class:`WatchdogInterlock`: lamps off when the watchdog has been still for 1 s;
   a separate task also checks it every ``INTERLOCK_CHECK_S``, so a trip does not wait for a late tick);
2. applies a changed drive setting (``OscillationEnabled``, ``Amplitude``, ``Period``) to the furnace;
3. advances the furnace over the past sample with the setpoints in force (zero if the interlock is off),
   in a worker thread so the OPC UA server's event loop keeps answering;
4. publishes TC1..TC4 (status Bad while a TC is dropped), ``Eta`` and ``LampsEnabled``, with the tick's
   wall time as the source timestamp.

A tick that comes late (a loaded machine) advances the furnace by every sample it missed before it
publishes, so the furnace's time stays the wall clock's.  With ``load_on_first_client`` the specimen
waits outside the furnace (at its initial temperature, the furnace's time at 0) until a client first
turns the lamps on with its watchdog, as when a lab loads a cold specimen and starts the twin; otherwise
the specimen sits in the furnace from the start and takes up the heat of its surroundings.
:class:`twin.furnace.emulator.timing.TimingRecord` keeps the reading and write times for the jitter and
latency figures.
"""

from __future__ import annotations

import asyncio
import logging
import time
from pathlib import Path
from typing import Any

import numpy as np

from twin.endpoints import parse_endpoint
from twin.furnace.emulator.address_space import AddressSpace, utc_now
from twin.furnace.emulator.interlock import WATCHDOG_TIMEOUT_S, WatchdogInterlock
from twin.furnace.emulator.timing import TimingRecord
from twin.furnace.interface import Furnace
from twin.furnace.opcua import nodes as names
from twin.furnace.opcua.nodes import NodeMap
from twin.furnace.opcua.security import PasswordUsers, secure_server
from twin.scenario import OscillationSpec

log = logging.getLogger(__name__)

INTERLOCK_CHECK_S = 0.05  # the watchdog is checked this often besides every tick


class FurnaceEmulator:
    """One furnace (normally a :class:`twin.furnace.simulated.SimulatedFurnace`) behind an OPC UA server.

    Parameters
    ----------
    furnace : the furnace served; its ``read`` / ``apply`` are called once per tick, in order
    endpoint : ``opc.tcp://host:port/path`` to listen on
    node_map : the address space (product.md's by default)
    eta_max : the drive's largest amplitude (m)
    T0 : the TCs' value before the first tick (K)
    security : ``none`` or ``sign-encrypt``; ``cert_dir`` holds the certificates
    users : user name -> password; when given, only they get a session
    load_on_first_client : the specimen enters the furnace when a client first enables the lamps
    """

    def __init__(self, furnace: Furnace, endpoint: str, node_map: NodeMap, *, eta_max: float, T0: float,
                 security: str = "none", cert_dir: str | Path = "furnace-data/opcua",
                 users: dict[str, str] | None = None, watchdog_s: float = WATCHDOG_TIMEOUT_S,
                 load_on_first_client: bool = False) -> None:
        self.furnace = furnace
        self.endpoint = endpoint
        self.node_map = node_map
        self.eta_max, self.T0 = float(eta_max), float(T0)
        self.security, self.cert_dir, self.users = security, Path(cert_dir), dict(users or {})
        self.interlock = WatchdogInterlock(watchdog_s)
        self.timing = TimingRecord()
        self.t_s = float(furnace.t_s)
        self.t = 0.0  # the furnace's time (s since the emulator started)
        self.overruns = 0  # ticks that had to catch up on missed samples
        self.loaded = not load_on_first_client  # the specimen is in the furnace (its time runs)
        self.server: Any = None
        self.space: AddressSpace | None = None
        self._oscillation = furnace.motion(0.0).oscillation
        self.ready = asyncio.Event()  # set once the first readings are published

    # ---- the server
    async def start(self) -> None:
        from asyncua import Server

        self.server = Server(user_manager=PasswordUsers(self.users) if self.users else None)
        await self.server.init()
        self.server.set_endpoint(self.endpoint)
        self.server.set_server_name("furnace-twin emulator")
        await secure_server(self.server, security=self.security, cert_dir=self.cert_dir,
                            host=parse_endpoint(self.endpoint).host, with_users=bool(self.users))
        self.space = AddressSpace(self.server, self.node_map, eta_max=self.eta_max, on_watchdog=self._watchdog)
        await self.space.build(self.T0, self._oscillation)
        await self.server.start()
        log.info("emulating the furnace at %s (security %s%s)", self.endpoint, self.security,
                 ", user names required" if self.users else "")

    def _watchdog(self, value: int) -> None:
        if self.interlock.feed(value, time.monotonic()):
            self.timing.write(time.monotonic())

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.stop()
            self.server = None

    # ---- one tick
    def _setpoints(self) -> np.ndarray:
        assert self.space is not None
        if not self.interlock.lamps_enabled:
            return np.zeros(len(self.node_map.group_names))
        return np.array([float(self.space.value(g)) for g in self.node_map.group_names])

    def _drive(self) -> OscillationSpec:
        assert self.space is not None
        return OscillationSpec(enabled=bool(self.space.value(names.OSCILLATION_ENABLED)),
                               amplitude=min(float(self.space.value(names.AMPLITUDE)), self.eta_max, 0.05),
                               period=float(self.space.value(names.PERIOD)))

    def _advance(self, steps: int, u: np.ndarray) -> Any:
        for _ in range(steps):
            self.furnace.apply(u, self.t)
            self.t = round(self.t + self.t_s, 9)
        return self.furnace.read(self.t), self.furnace.motion(self.t).eta

    async def _publish(self, readings: Any, eta: float, stamp: Any) -> None:
        assert self.space is not None
        values: dict[str, tuple[Any, bool]] = {}
        for i, tc in enumerate(names.TC_NAMES):
            status = readings.status[i]
            if status != "missing":  # a missing reading is simply not published this sample
                values[tc] = (float(readings.values[i]), status == "good" and bool(np.isfinite(readings.values[i])))
        values[names.ETA] = (float(eta), True)
        values[names.LAMPS_ENABLED] = (self.interlock.lamps_enabled, True)
        await self.space.publish(values, stamp)

    async def _watch_interlock(self, stop: asyncio.Event) -> None:
        """Trip the interlock as soon as the watchdog is overdue, and publish ``LampsEnabled`` at once."""
        assert self.space is not None
        while not stop.is_set():
            if self.interlock.check(time.monotonic()):
                await self.space.publish({names.LAMPS_ENABLED: (False, True)}, utc_now())
            try:
                await asyncio.wait_for(stop.wait(), timeout=INTERLOCK_CHECK_S)
            except TimeoutError:
                pass

    async def run(self, stop: asyncio.Event) -> None:
        """Tick in real time until ``stop`` is set."""
        watcher = asyncio.get_running_loop().create_task(self._watch_interlock(stop))
        try:
            await self._ticks(stop)
        finally:
            watcher.cancel()

    async def _ticks(self, stop: asyncio.Event) -> None:
        assert self.space is not None
        readings, eta = self.furnace.read(0.0), self.furnace.motion(0.0).eta
        start = time.monotonic()
        await self._publish(readings, eta, utc_now())
        self.ready.set()
        k = 0
        while not stop.is_set():
            due = start + (k + 1) * self.t_s
            try:
                await asyncio.wait_for(stop.wait(), timeout=max(due - time.monotonic(), 0.0))
                break
            except TimeoutError:
                pass
            now = time.monotonic()
            stamp = utc_now()
            steps = max(int((now - start) / self.t_s + 1e-9) - k, 1)
            if steps > 1:
                self.overruns += 1
                log.debug("tick %d came %.1f ms late: advancing %d samples", k + 1, 1000 * (now - due), steps)
            k += steps
            self.interlock.check(now)
            if not self.loaded:
                if not self.interlock.lamps_enabled:  # still waiting outside: same state, a new time stamp
                    await self._publish(readings, eta, stamp)
                    continue
                self.loaded, steps = True, 1
                log.info("a client enabled the lamps: the specimen is in the furnace, its time starts")
            spec = self._drive()
            if spec != self._oscillation:
                self.furnace.set_oscillation(spec, self.t)
                self._oscillation = spec
                log.info("drive: %s at t = %.1f s", spec.model_dump(), self.t)
            self.timing.reading(now)
            readings, eta = await asyncio.to_thread(self._advance, steps, self._setpoints())
            await self._publish(readings, eta, stamp)

    async def serve(self, stop: asyncio.Event) -> None:
        """Start, tick until ``stop``, stop (the lamps are off with the server gone)."""
        await self.start()
        try:
            await self.run(stop)
        finally:
            await self.stop()
            log.info("emulator stopped at t = %.1f s: %d interlock trips, %d late ticks", self.t,
                     self.interlock.trips, self.overruns)
