"""The hardware-in-the-loop emulator: a simulated furnace served as an OPC UA server.

In **real time** (the default), every sample time t_s of the wall clock (ticks at fixed times from the start,
so lateness does not accumulate) the emulator

1. checks the interlock (:class:`WatchdogInterlock`: lamps off when the watchdog has been still for 1 s;
   a separate task also checks it every ``INTERLOCK_CHECK_S``, so a trip does not wait for a late tick);
2. applies a changed drive setting (``OscillationEnabled``, ``Amplitude``, ``Period``) to the furnace;
3. advances the furnace over the past sample with the setpoints in force (zero if the interlock is off),
   in a worker thread so the OPC UA server's event loop keeps answering;
4. publishes TC1..TC4 (status Bad while a TC is dropped), ``Eta`` and ``LampsEnabled``, stamped with the
   sample's own time on the emulator's clock (start + k t_s: when the furnace took that sample, also when
   the tick that computed it ran late).

A tick that comes late (a loaded machine) advances the furnace by every sample it missed before it
publishes, so the furnace's time stays the wall clock's.  With ``load_on_first_client`` the specimen
waits outside the furnace (at its initial temperature, the furnace's time at 0) until a client first
turns the lamps on with its watchdog, as when a lab loads a cold specimen and starts the twin; otherwise
the specimen sits in the furnace from the start and takes up the heat of its surroundings.

In **lock step** (``clock="lock-step"``, ``furnace-twin emulate --lock-step``) there is no wall clock: the
furnace advances by one sample each time a client's Write request changes the watchdog, with the setpoints
of that request, and publishes the new sample stamped start + t (its own time).  A client that reads each
sample, computes and writes then runs exactly the loop it would run in process (the exact transport test);
the node ``LockStep`` (true) tells it so.  Without a wall clock there is no watchdog timeout either: a silent
client stops the furnace's time, and each write that changes the watchdog is the sign of life its step needs.

:class:`twin.furnace.emulator.timing.TimingRecord` keeps the reading and write times for the jitter and
latency figures.
"""

from __future__ import annotations

import asyncio
import datetime
import logging
import time
from pathlib import Path
from typing import Any, Literal

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
Clock = Literal["realtime", "lock-step"]


class FurnaceEmulator:
    """One furnace (normally a :class:`twin.furnace.simulated.SimulatedFurnace`) behind an OPC UA server.

    Parameters
    ----------
    furnace : the furnace served; its ``read`` / ``apply`` are called once per sample, in order
    endpoint : ``opc.tcp://host:port/path`` to listen on
    node_map : the address space (product.md's by default)
    eta_max : the drive's largest amplitude (m)
    T0 : the TCs' value before the first sample (K)
    security : ``none`` or ``sign-encrypt``; ``cert_dir`` holds the certificates
    users : user name -> password; when given, only they get a session
    load_on_first_client : the specimen enters the furnace when a client first enables the lamps (real time)
    clock : ``"realtime"`` (ticks of the wall clock) or ``"lock-step"`` (one sample per watchdog write)
    """

    def __init__(self, furnace: Furnace, endpoint: str, node_map: NodeMap, *, eta_max: float, T0: float,
                 security: str = "none", cert_dir: str | Path = "furnace-data/opcua",
                 users: dict[str, str] | None = None, watchdog_s: float = WATCHDOG_TIMEOUT_S,
                 load_on_first_client: bool = False, clock: Clock = "realtime") -> None:
        self.furnace = furnace
        self.endpoint = endpoint
        self.node_map = node_map
        self.eta_max, self.T0 = float(eta_max), float(T0)
        self.security, self.cert_dir, self.users = security, Path(cert_dir), dict(users or {})
        self.interlock = WatchdogInterlock(watchdog_s)
        self.timing = TimingRecord()
        self.t_s = float(furnace.t_s)
        self.clock: Clock = clock
        self.t = 0.0  # the furnace's time (s since the emulator started)
        self.overruns = 0  # ticks that had to catch up on missed samples
        self.loaded = not load_on_first_client or clock == "lock-step"  # the specimen is in the furnace
        self.server: Any = None
        self.space: AddressSpace | None = None
        self._oscillation = furnace.motion(0.0).oscillation
        self._epoch: Any = None  # the UTC time of sample 0 (stamps are epoch + the sample's time)
        self._fed = False  # the request being served changed the watchdog
        self._steps_wanted = 0  # lock step: samples the clients' writes asked for, not yet computed
        self._wake = asyncio.Event()
        self.ready = asyncio.Event()  # set once the first readings are published

    # ---- the server
    async def start(self) -> None:
        from asyncua import Server
        from asyncua.common.callback import CallbackType

        self.server = Server(user_manager=PasswordUsers(self.users) if self.users else None)
        await self.server.init()
        self.server.set_endpoint(self.endpoint)
        self.server.set_server_name("furnace-twin emulator")
        await secure_server(self.server, security=self.security, cert_dir=self.cert_dir,
                            host=parse_endpoint(self.endpoint).host, with_users=bool(self.users))
        self.space = AddressSpace(self.server, self.node_map, eta_max=self.eta_max, on_watchdog=self._watchdog)
        await self.space.build(self.T0, self._oscillation, lock_step=self.clock == "lock-step")
        self.server.subscribe_server_callback(CallbackType.PostWrite, self._after_write)
        await self.server.start()
        log.info("emulating the furnace at %s (security %s%s, clock %s)", self.endpoint, self.security,
                 ", user names required" if self.users else "", self.clock)

    def _watchdog(self, value: int) -> None:
        if self.interlock.feed(value, time.monotonic()):
            self.timing.write(time.monotonic())
            self._fed = True

    def _after_write(self, event: Any, dispatcher: Any) -> None:
        """After a whole Write request: in lock step, a changed watchdog asks for the next sample (computed with
        every setpoint of that request, whatever their order in it)."""
        if self._fed and self.clock == "lock-step":
            self._steps_wanted += 1
            self._wake.set()
        self._fed = False

    async def stop(self) -> None:
        if self.server is not None:
            await self.server.stop()
            self.server = None

    # ---- one sample
    def _setpoints(self) -> tuple[np.ndarray, int | None]:
        """The setpoints in force and the watchdog value of the write that set them (``None``: lamps off)."""
        assert self.space is not None
        if not self.interlock.lamps_enabled:
            return np.zeros(len(self.node_map.group_names)), None
        return np.array([float(self.space.value(g)) for g in self.node_map.group_names]), self.interlock.value

    def _drive(self) -> OscillationSpec:
        assert self.space is not None
        # the address space clamped both numbers to what this drive takes (0..eta_max, 1..600 s): this furnace's
        # limits, not the default furnace's the model's own validation would apply
        return OscillationSpec.model_construct(enabled=bool(self.space.value(names.OSCILLATION_ENABLED)),
                                               amplitude=float(self.space.value(names.AMPLITUDE)),
                                               period=float(self.space.value(names.PERIOD)))

    def _follow_drive(self) -> None:
        spec = self._drive()
        if spec != self._oscillation:
            self.furnace.set_oscillation(spec, self.t)
            self._oscillation = spec
            log.info("drive: %s at t = %.1f s", spec.model_dump(), self.t)

    def _advance(self, steps: int, setpoints: tuple[np.ndarray, int | None]) -> Any:
        u, watchdog = setpoints
        for _ in range(steps):
            self.furnace.apply(u, self.t)
            self.t = round(self.t + self.t_s, 9)
            self.timing.step(watchdog)
        return self.furnace.read(self.t), self.furnace.motion(self.t).eta

    def _stamp(self, t: float) -> Any:
        """The source timestamp of the sample at emulator time ``t`` (s)."""
        return self._epoch + datetime.timedelta(seconds=t)

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
        """Serve samples (in real time, or one per watchdog write in lock step) until ``stop`` is set."""
        if self.clock == "lock-step":  # no wall clock: a silent client stops the furnace's time, not its lamps
            await self._lock_step(stop)
            return
        watcher = asyncio.get_running_loop().create_task(self._watch_interlock(stop))
        try:
            await self._ticks(stop)
        finally:
            watcher.cancel()

    async def _lock_step(self, stop: asyncio.Event) -> None:
        assert self.space is not None
        self._epoch = utc_now()
        await self._publish(self.furnace.read(0.0), self.furnace.motion(0.0).eta, self._stamp(0.0))
        self.ready.set()
        stopping = asyncio.get_running_loop().create_task(stop.wait())
        try:
            while not stop.is_set():
                waking = asyncio.get_running_loop().create_task(self._wake.wait())
                await asyncio.wait({waking, stopping}, return_when=asyncio.FIRST_COMPLETED)
                waking.cancel()
                self._wake.clear()
                while self._steps_wanted > 0 and not stop.is_set():
                    self._steps_wanted -= 1
                    self._follow_drive()
                    self.timing.reading(time.monotonic())
                    readings, eta = await asyncio.to_thread(self._advance, 1, self._setpoints())
                    await self._publish(readings, eta, self._stamp(self.t))
        finally:
            stopping.cancel()

    async def _ticks(self, stop: asyncio.Event) -> None:
        assert self.space is not None
        readings, eta = self.furnace.read(0.0), self.furnace.motion(0.0).eta
        start, self._epoch = time.monotonic(), utc_now()
        await self._publish(readings, eta, self._epoch)
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
            steps = max(int((now - start) / self.t_s + 1e-9) - k, 1)
            if steps > 1:
                self.overruns += 1
                log.debug("tick %d came %.1f ms late: advancing %d samples", k + 1, 1000 * (now - due), steps)
            k += steps
            stamp = self._stamp(k * self.t_s)  # when this sample is due on the emulator's clock
            self.interlock.check(now)
            if not self.loaded:
                if not self.interlock.lamps_enabled:  # still waiting outside: same state, a new time stamp
                    await self._publish(readings, eta, stamp)
                    continue
                self.loaded, steps = True, 1
                log.info("a client enabled the lamps: the specimen is in the furnace, its time starts")
            self._follow_drive()
            self.timing.reading(now)
            readings, eta = await asyncio.to_thread(self._advance, steps, self._setpoints())
            await self._publish(readings, eta, stamp)

    async def serve(self, stop: asyncio.Event) -> None:
        """Start, serve until ``stop``, stop (the lamps are off with the server gone)."""
        await self.start()
        try:
            await self.run(stop)
        finally:
            await self.stop()
            log.info("emulator stopped at t = %.1f s: %d interlock trips, %d late ticks", self.t,
                     self.interlock.trips, self.overruns)
