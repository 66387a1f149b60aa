"""A real furnace over OPC UA behind the furnace boundary (:class:`twin.furnace.interface.Furnace`).

The OPC UA client runs on its own thread and event loop (never the web server's, never the run's):
the subscription fills a :class:`twin.furnace.opcua.samples.SampleBuffer`, and the run's thread

* reads sample t_j = j t_s with :meth:`OpcUaFurnace.read`, which waits for the furnace's sample j (the
  furnace's clock drives the run) until it is late; what did not come is ``missing`` and the estimator
  predicts without it.  ``read(0.0)`` starts the run clock at the furnace's newest sample.  A reading the link
  could not bring is ``unlinked`` instead (:func:`unlinked_channels`: the link is down, or on a new connection
  that channel's subscription has not delivered yet), so the fault detection does not take it for the TC's
  dropout;
* applies the group powers with :meth:`OpcUaFurnace.apply`: one Write request with the six setpoints and
  the watchdog (incremented every sample), sent without waiting for the answer.

A link lost for longer than ``options.reconnect_s`` raises :class:`twin.furnace.interface.FurnaceLost`
from :meth:`read`; so does a furnace that sends no readings that long.  :meth:`close` commands the lamps
off where the link still allows.  A real furnace has no true field (:meth:`true_field` is ``None``).

What the run's events learn from the furnace (:meth:`OpcUaFurnace.drain_events`): a link lost and restored;
the furnace's own interlock switching the lamps off (``LampsEnabled`` false while the twin was driving them)
and on again; the twin itself falling behind the furnace's clock (samples taken after their deadline: the
commands for them reached the furnace late or not at all, which no missing reading would show).

A furnace that says it runs in lock step (the emulator's ``LockStep`` node, ``furnace-twin emulate
--lock-step``) computes each sample only after the twin's write: then no wall-clock deadline applies and the
run over OPC UA is the in-process run, sample for sample (:mod:`twin.furnace.opcua.samples`).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import math
import threading
import time
from collections import deque
from collections.abc import Coroutine
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from twin.config import FurnaceConfig
from twin.furnace.interface import FurnaceLost, Motion, Readings, TCStatus
from twin.furnace.opcua import nodes as names
from twin.furnace.opcua.link import FurnaceLink, FurnaceUnavailable, LinkSettings
from twin.furnace.opcua.nodes import NodeMap, load_mapping
from twin.furnace.opcua.options import OpcUaOptions
from twin.furnace.opcua.samples import SampleBuffer
from twin.scenario import OscillationSpec

log = logging.getLogger(__name__)
Array = NDArray[np.float64]
T = TypeVar("T")

CHANNELS = (*names.TC_NAMES, names.ETA)  # what one sample holds, in this order
ANCHOR_TIMEOUT_S = 2.0  # the furnace must publish within this long when a run starts
WRITE_TIMEOUT_S = 1.0  # a blocking write (oscillation, lamps off) waits at most this long
FURNACE_WATCHDOG_S = 1.0  # product.md: a furnace switches its lamps off when the watchdog is still this long
_COUNTER_MODULUS = {"Byte": 2**8, "SByte": 2**7, "UInt16": 2**16, "Int16": 2**15, "UInt32": 2**32,
                    "Int32": 2**31, "UInt64": 2**64, "Int64": 2**63}


def unlinked_channels(state: str, began: float, connected_since: float, heard: list[float], now: float,
                      grace_s: float) -> list[bool]:
    """Per channel: is a reading that did not come the link's doing rather than the furnace's?

    Yes while the link is not ``connected`` (down, reconnecting, given up); and, for ``grace_s`` after a
    (re)connection (the time a request may take, ``options.connect_timeout_s``), for a channel that has sent
    nothing over it yet (``heard[i]``: monotonic s of its latest reading, older than ``began``, when the
    connection's attempt began): a subscription's first notification answers its creation, and a busy server
    can send some channels' seconds after others'.  After the grace a silent channel is ``missing`` again: a TC
    that is dead on the furnace is still found, at most ``grace_s`` later.

    >>> unlinked_channels("connected", 10.0, 10.5, [10.6, 9.9], now=11.0, grace_s=5.0)
    [False, True]
    >>> unlinked_channels("connected", 10.0, 10.5, [10.6, 9.9], now=16.0, grace_s=5.0)
    [False, False]
    >>> unlinked_channels("reconnecting", 10.0, 10.5, [10.6, 9.9], now=16.0, grace_s=5.0)
    [True, True]
    """
    if state != "connected":
        return [True] * len(heard)
    fresh = now - connected_since < grace_s
    return [fresh and h < began for h in heard]


class _IoThread:
    """An event loop on a daemon thread; coroutines are handed to it from other threads."""

    def __init__(self, name: str) -> None:
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, name=name, daemon=True)
        self._thread.start()

    def submit(self, coro: Coroutine[Any, Any, T]) -> concurrent.futures.Future[T]:
        return asyncio.run_coroutine_threadsafe(coro, self.loop)

    def call(self, coro: Coroutine[Any, Any, T], timeout: float) -> T:
        return self.submit(coro).result(timeout=timeout)

    def stop(self) -> None:
        if self.loop.is_running():
            self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(timeout=5.0)
        if not self._thread.is_alive():
            self.loop.close()


class OpcUaFurnace:
    """The furnace at ``endpoint``, addressed through ``options.mapping`` (product.md's address space by default).

    Parameters
    ----------
    cfg : the twin's furnace (sample time, lamp groups, TC positions)
    endpoint : ``opc.tcp://host:port/path``
    options : link settings (security, credentials, mapping, reconnection, lateness)
    cert_dir : where this twin's certificate and the trusted ones are (``<data dir>/opcua``)
    tc4 : relative position of the validation thermocouple TC4 on this specimen
    oscillation : the drive's settings commanded at the start
    """

    kind = "opcua"
    realtime = True

    def __init__(self, cfg: FurnaceConfig, endpoint: str, *, options: OpcUaOptions, cert_dir: str | Path,
                 tc4: tuple[float, float] | None = None, oscillation: OscillationSpec | None = None) -> None:
        self.cfg = cfg
        self.endpoint = endpoint
        self.options = options
        self.node_map: NodeMap = load_mapping(options.mapping, [g.name for g in cfg.lamps.groups])
        self._groups = tuple(g.name for g in cfg.lamps.groups)
        self._tc_positions = np.asarray(cfg.tc_positions(tc4), float)
        self._buffer = SampleBuffer(self.t_s, len(CHANNELS), late_s=options.late_fraction * self.t_s)
        self._io = _IoThread(f"opcua-{endpoint}")
        self._link = FurnaceLink(LinkSettings(endpoint, options, Path(cert_dir), self.node_map, CHANNELS,
                                              watched=(names.LAMPS_ENABLED,)), self._reading, self._on_state)
        self._reading_connection = -math.inf  # the connection (its connected_since) the last reading came on
        self._heard = [-math.inf] * len(CHANNELS)  # monotonic s of each channel's latest reading
        self._oscillation = oscillation or OscillationSpec()
        self._since = 0.0
        self._eta = 0.0
        self._pending_write: concurrent.futures.Future[None] | None = None
        self.writes_failed = 0
        self.lock_step = False
        self._events: deque[str] = deque()  # the furnace's own reports (beside the link's), for the run's events
        self._last_write = -math.inf  # monotonic s
        self._read_started = -math.inf  # monotonic s
        self._taken_late = 0.0  # s after its deadline the last sample was taken
        self._lamps: tuple[bool, float] | None = None  # (LampsEnabled, connection it came on) as last said
        self._lamps_driven = False  # the twin has enabled the lamps with its watchdog
        self._lamps_off_at: float | None = None  # run time at which the furnace switched them off
        self._behind = 0  # samples in the current run of samples the twin answered late
        self._behind_worst = (0.0, 0.0)  # the current run's longest lateness (s) and the sample's time (s)
        self.overdue_samples = 0  # samples answered late (taken after their deadline, or command after the next)
        try:
            self._io.call(self._link.open(), timeout=4 * options.connect_timeout_s)
            if names.LOCK_STEP in self._link.nodes:
                said = self._io.call(self._link.read([names.LOCK_STEP]), timeout=options.connect_timeout_s)
                self.lock_step = bool(said[names.LOCK_STEP])
                self._buffer.lock_step = self.lock_step
            start = self._io.call(self._link.read([names.WATCHDOG]), timeout=options.connect_timeout_s)
            self._watchdog_modulus = _COUNTER_MODULUS.get(self._link.nodes[names.WATCHDOG].variant_type.name, 2**15)
            self._watchdog = int(start[names.WATCHDOG] or 0) % self._watchdog_modulus
            self._write({**dict.fromkeys(self._groups, 0.0), **self._drive_values(self._oscillation)})
        except FurnaceUnavailable:
            self._shutdown()
            raise
        except Exception as exc:
            self._shutdown()
            raise FurnaceUnavailable(f"{endpoint}: setting up the furnace failed: {type(exc).__name__}: {exc}") from exc
        except BaseException:
            self._shutdown()
            raise

    # ---- the Furnace protocol
    @property
    def t_s(self) -> float:
        return float(self.cfg.sampling.t_s)

    @property
    def tc_positions(self) -> Array:
        return self._tc_positions

    @property
    def late_readings(self) -> int:
        """Readings that came after their sample was given up (they were dropped)."""
        return self._buffer.dropped_late

    def _check_alive(self) -> None:
        link = self._link
        if link.lost:
            raise FurnaceLost(link.lost_reason or "the link to the furnace is lost")
        # in lock step the furnace only answers: it is silent if it does not answer while the twin waits for it
        waited = max(self._last_write, self._read_started) if self.lock_step else -math.inf
        heard = max(self._buffer.last_arrival, link.connected_since, waited)
        silent = time.monotonic() - heard
        if link.state == "connected" and silent > max(self.options.reconnect_s, 2 * self.t_s):
            link.declare_lost(f"no readings from the furnace for {silent:.1f} s (allowed: "
                              f"{self.options.reconnect_s:g} s)")
            raise FurnaceLost(link.lost_reason or "the furnace sends no readings")

    def read(self, t: float) -> Readings:
        """Sample j = round(t / t_s) of the furnace's clock; ``read(0.0)`` starts that clock."""
        j = int(round(t / self.t_s))
        self._read_started = time.monotonic()
        self._check_alive()
        if j == 0:
            if self._buffer.anchor(ANCHOR_TIMEOUT_S) is None:
                raise FurnaceLost(f"the furnace at {self.endpoint} sent no readings within {ANCHOR_TIMEOUT_S:g} s")
        slot = self._buffer.take(j, give_up=self._give_up)
        self._check_alive()
        self._taken_late = self._buffer.overdue_s
        origin = self._buffer.origin or 0.0
        link = self._link
        unlinked = unlinked_channels(link.state, link.connection_began, link.connected_since, self._heard[:4],
                                     time.monotonic(), self.options.connect_timeout_s)
        values, stamps, status = np.full(4, np.nan), np.full(4, np.nan), []
        for i in range(4):
            r = slot[i]
            st: TCStatus = ("unlinked" if unlinked[i] else "missing") if r is None else \
                ("good" if r.good and math.isfinite(r.value) else "bad")
            status.append(st)
            if r is not None:
                stamps[i] = r.source_s - origin
                if st == "good":
                    values[i] = r.value
        eta = slot[4]
        if eta is not None and eta.good and math.isfinite(eta.value):
            self._eta = eta.value
        return Readings(values=values, timestamps=stamps, status=tuple(status))

    def _give_up(self) -> bool:
        """Stop waiting for a sample: the link is lost, or (lock step: no deadline) the furnace fell silent."""
        if self._link.lost:
            return True
        if not self.lock_step:
            return False
        try:
            self._check_alive()
        except FurnaceLost:
            return True
        return False

    def _note_behind(self, j: int, taken_late: float, sent_late: float) -> None:
        """Sample j was taken after its deadline, or its command sent after the next sample was due: the furnace
        held an older command meanwhile (its watchdog may have switched the lamps off).  An event when a run of
        such samples starts, and when the twin has caught up; the latter names the run's longest lateness, which
        need not be its first (a loaded machine's 0.1 s, then a 1.3 s pause)."""
        t = j * self.t_s
        late = max(taken_late, sent_late)
        if late > 0.0:
            self.overdue_samples += 1
            self._behind += 1
            if self._behind == 1:
                self._behind_worst = (late, t)
                what = (f"the sample was taken {taken_late:.2f} s after it was due" if taken_late > 0.0 else
                        f"its lamp command went out {sent_late:.2f} s after the next sample was due")
                self._events.append(f"the twin fell behind the furnace at t = {t:.1f} s: {what} (the furnace held "
                                    "an older command meanwhile)")
            elif late > self._behind_worst[0]:
                self._behind_worst = (late, t)
        elif self._behind:
            worst, t_worst = self._behind_worst
            samples = f"{self._behind} sample{'s' if self._behind > 1 else ''}"
            self._events.append(f"the twin caught up with the furnace at t = {t:.1f} s after {samples} late, the "
                                f"longest {worst:.2f} s at t = {t_worst:.1f} s ({self.overdue_samples} in this run)")
            self._behind = 0

    def _reading(self, channel: int, value: float, good: bool, source_s: float, arrival: float) -> None:
        """A reading into the sample buffer (the OPC UA thread); the first after a reconnection has the buffer
        learn the new subscription's arrival delays (:meth:`SampleBuffer.relearn`)."""
        connection = self._link.connected_since
        if connection != self._reading_connection:
            if self._reading_connection > -math.inf:
                self._buffer.relearn()
            self._reading_connection = connection
        self._heard[channel] = max(self._heard[channel], arrival)
        self._buffer.add(channel, value, good, source_s, arrival)

    def _on_state(self, name: str, value: Any, good: bool, source_s: float) -> None:
        """``LampsEnabled`` as the furnace reports it (the OPC UA thread): its interlock turning the lamps off
        while the twin drives them, and on again."""
        if name != names.LAMPS_ENABLED or not good or value is None:
            return
        on = bool(value)
        origin = self._buffer.origin
        t = (source_s - origin) if origin is not None else math.nan
        relinked = self._lamps is not None and self._lamps[1] != self._link.connected_since
        was_on = self._lamps is None or self._lamps[0]
        if on and not self._lamps_driven and self._last_write > -math.inf:
            self._lamps_driven = True
        elif not on and self._lamps_driven and self._lamps_off_at is None and (was_on or relinked):
            self._lamps_off_at = t
            self._events.append(
                f"the furnace's lamps were off when the link returned at t = {t:.1f} s (LampsEnabled false: its "
                "watchdog, or a restarted server)" if relinked else
                f"the furnace switched its lamps off at t = {t:.1f} s (LampsEnabled false: its watchdog interlock "
                "did not see the twin's writes in time)")
        elif on and self._lamps_off_at is not None:
            self._events.append(f"the furnace enabled its lamps again at t = {t:.1f} s after "
                                f"{t - self._lamps_off_at:.2f} s off")
            self._lamps_off_at = None
        self._lamps = (on, self._link.connected_since)

    def apply(self, u: Array, t: float) -> None:
        """Write the six setpoints (clipped to [0, 1]) and the next watchdog value; do not wait for the answer."""
        if self._link.state != "connected" or self._link.lost:
            return  # reconnecting or given up: the furnace's watchdog switches its lamps off
        prev = self._pending_write
        if prev is not None and prev.done() and prev.exception() is not None:
            self.writes_failed += 1
            log.warning("writing the lamp setpoints failed: %s", prev.exception())
        self._watchdog = (self._watchdog + 1) % self._watchdog_modulus
        values = {g: float(np.clip(v, 0.0, 1.0)) for g, v in zip(self._groups, np.asarray(u, float), strict=True)}
        values[names.WATCHDOG] = self._watchdog
        self._last_write = time.monotonic()
        self._pending_write = self._io.submit(self._link.write(values))
        if not self.lock_step and self._buffer.origin is not None:
            j = int(round(t / self.t_s))
            sent_late = max(self._last_write - self._buffer.due(j + 1), 0.0)
            self._note_behind(j, self._taken_late, sent_late)
            self._taken_late = 0.0

    def delivered(self, u: Array, t: float) -> Array:
        """What the furnace holds from t: ``u`` while the twin's writes reach it; with the link down, the last
        command until the furnace's watchdog switches the lamps off (``FURNACE_WATCHDOG_S`` after the last write,
        product.md's interlock), then nothing."""
        if self._link.state == "connected" and not self._link.lost:
            return np.asarray(u, float)
        held = time.monotonic() - self._last_write < FURNACE_WATCHDOG_S
        return np.asarray(u, float) if held else np.zeros(len(self._groups))

    def motion(self, t: float) -> Motion:
        return Motion(eta=self._eta, oscillation=self._oscillation, since=self._since)

    def _drive_values(self, spec: OscillationSpec) -> dict[str, Any]:
        return {names.OSCILLATION_ENABLED: spec.enabled, names.AMPLITUDE: spec.amplitude, names.PERIOD: spec.period}

    def set_oscillation(self, spec: OscillationSpec, t: float) -> None:
        """Command the drive (enabled, amplitude, period in one Write request); raises if the furnace refuses."""
        self._write(self._drive_values(spec))
        self._oscillation, self._since = spec, float(t)

    def _write(self, values: dict[str, Any]) -> None:
        self._io.call(self._link.write(values), timeout=WRITE_TIMEOUT_S + self.options.connect_timeout_s)

    def true_field(self) -> None:
        return None

    def drain_events(self) -> tuple[str, ...]:
        out = []
        for queue in (self._link.events, self._events):
            while queue:
                out.append(queue.popleft())
        return tuple(out)

    def close(self) -> None:
        """Lamps off (where the link allows: also when the furnace was given up with its link up), then disconnect."""
        if self._link.state == "connected":
            try:
                self._write(dict.fromkeys(self._groups, 0.0))
                log.info("lamps commanded off at %s", self.endpoint)
            except Exception as exc:
                log.warning("could not command the lamps off at %s: %s", self.endpoint, exc)
        self._shutdown()

    def _shutdown(self) -> None:
        try:
            self._io.call(self._link.close(), timeout=3.0)
        except Exception:
            log.debug("closing the OPC UA link", exc_info=True)
        self._io.stop()
