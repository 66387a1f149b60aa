"""A real furnace over OPC UA behind the furnace boundary (:class:`twin.furnace.interface.Furnace`).

The OPC UA client runs on its own thread and event loop (never the web server's, never the run's):
the subscription fills a :class:`twin.furnace.opcua.samples.SampleBuffer`, and the run's thread

* reads sample t_j = j t_s with :meth:`OpcUaFurnace.read`, which waits for the furnace's sample j (the
  furnace's clock drives the run) until it is late; what did not come is ``missing`` and the estimator
  predicts without it.  ``read(0.0)`` starts the run clock at the furnace's newest sample;
* applies the group powers with :meth:`OpcUaFurnace.apply`: one Write request with the six setpoints and
  the watchdog (incremented every sample), sent without waiting for the answer.

A link lost for longer than ``options.reconnect_s`` raises :class:`twin.furnace.interface.FurnaceLost`
from :meth:`read`; so does a furnace that sends no readings that long.  :meth:`close` commands the lamps
off where the link still allows.  A real furnace has no true field (:meth:`true_field` is ``None``).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import math
import threading
import time
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
_COUNTER_MODULUS = {"Byte": 2**8, "SByte": 2**7, "UInt16": 2**16, "Int16": 2**15, "UInt32": 2**32,
                    "Int32": 2**31, "UInt64": 2**64, "Int64": 2**63}


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
        self._link = FurnaceLink(LinkSettings(endpoint, options, Path(cert_dir), self.node_map, CHANNELS),
                                 self._buffer.add)
        self._oscillation = oscillation or OscillationSpec()
        self._since = 0.0
        self._eta = 0.0
        self._pending_write: concurrent.futures.Future[None] | None = None
        self.writes_failed = 0
        try:
            self._io.call(self._link.open(), timeout=4 * options.connect_timeout_s)
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
        silent = time.monotonic() - max(self._buffer.last_arrival, link.connected_since)
        if link.state == "connected" and silent > max(self.options.reconnect_s, 2 * self.t_s):
            link.declare_lost(f"no readings from the furnace for {silent:.1f} s (allowed: "
                              f"{self.options.reconnect_s:g} s)")
            raise FurnaceLost(link.lost_reason or "the furnace sends no readings")

    def read(self, t: float) -> Readings:
        """Sample j = round(t / t_s) of the furnace's clock; ``read(0.0)`` starts that clock."""
        j = int(round(t / self.t_s))
        self._check_alive()
        if j == 0:
            if self._buffer.anchor(ANCHOR_TIMEOUT_S) is None:
                raise FurnaceLost(f"the furnace at {self.endpoint} sent no readings within {ANCHOR_TIMEOUT_S:g} s")
        slot = self._buffer.take(j, give_up=lambda: self._link.lost)
        self._check_alive()
        origin = self._buffer.origin or 0.0
        values, stamps, status = np.full(4, np.nan), np.full(4, np.nan), []
        for i in range(4):
            r = slot[i]
            st: TCStatus = "missing" if r is None else ("good" if r.good and math.isfinite(r.value) else "bad")
            status.append(st)
            if r is not None:
                stamps[i] = r.source_s - origin
                if st == "good":
                    values[i] = r.value
        eta = slot[4]
        if eta is not None and eta.good and math.isfinite(eta.value):
            self._eta = eta.value
        return Readings(values=values, timestamps=stamps, status=tuple(status))

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
        self._pending_write = self._io.submit(self._link.write(values))

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
        while self._link.events:
            out.append(self._link.events.popleft())
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
