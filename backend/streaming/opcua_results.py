"""The twin as an OPC UA server: its own results for the plant's SCADA and historian (issue 24, product.md).

``furnace-twin serve --opcua-endpoint opc.tcp://127.0.0.1:4841/furnace-twin/results/`` (off by default) serves,
read-only, an object ``Twin`` under Objects (namespace ``urn:furnace-twin:results``) with
``Runs/Current/{RunId, Status, T, T_ref, T_mean_hat, T_sup_hat, TC4Error, FieldSigmaMean, LampEfficiency,
Emissivity}`` and the estimated field's extremes ``FieldMin``, ``FieldMax``: the newest run this server drives,
else the last one that ran (its last sample, its ending).  Every value carries the sample's time as its source
timestamp (the wall clock when the twin computed it); one the twin does not have (no calibration, no field
uncertainty, no TC4 reading) is published with status ``BadNoData``, every value of a run without a sample yet
with ``BadWaitingForInitialData``.  Temperatures are in K with their
``EngineeringUnits`` (UNECE ``KEL``), times in s, the calibrated parameters relative deviations like a
scenario's ``mismatch``.

Security follows the twin's own settings (``FURNACE_TWIN_OPCUA_SECURITY``): ``sign-encrypt`` serves only
Basic256Sha256 Sign & Encrypt with the certificate ``<data dir>/opcua/results-cert.der`` and accepts the client
certificates in ``<data dir>/opcua/trusted/``; without security it serves only on a loopback address.  Every
session is a plain user: a write answers ``BadNotWritable``, adding or deleting nodes is refused.

The server runs on its own thread and event loop; it reads the runs through the manager's public methods
(:meth:`backend.runs.manager.RunManager.live_runs`, ``latest``, ``runs``) ten times a second.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import datetime
import json
import logging
import math
import threading
from pathlib import Path
from typing import Any

import numpy as np

log = logging.getLogger(__name__)

NAMESPACE = "urn:furnace-twin:results"
PATH = ("Twin", "Runs", "Current")
POLL_S = 0.1  # how often the newest sample is looked for
UNECE = "http://www.opcfoundation.org/UA/units/un/cefact"
#: name -> (OPC UA type, unit (UNECE common code, symbol) or None, description)
NODES: dict[str, tuple[str, tuple[str, str] | None, str]] = {
    "RunId": ("String", None, "the run shown here: the newest this twin drives, else the last one that ran"),
    "Status": ("String", None, "running, degraded (no thermocouple reading reaches the estimate), or how it ended"),
    "T": ("Double", ("SEC", "s"), "run time of the sample"),
    "T_ref": ("Double", ("KEL", "K"), "the reference of the fillet mean"),
    "T_mean_hat": ("Double", ("KEL", "K"), "estimated fillet mean temperature"),
    "T_sup_hat": ("Double", ("KEL", "K"), "estimated T_sup: max over the fillet of |T - T_ref|"),
    "TC4Error": ("Double", ("KEL", "K"), "validation thermocouple TC4 minus the estimate there"),
    "FieldSigmaMean": ("Double", ("KEL", "K"), "standard deviation of the estimated fillet mean T_mean_hat"),
    "LampEfficiency": ("Double", None, "calibrated lamp efficiency, relative deviation from the model"),
    "Emissivity": ("Double", None, "calibrated emissivity, relative deviation from the model"),
    "FieldMin": ("Double", ("KEL", "K"), "coldest cell of the estimated field"),
    "FieldMax": ("Double", ("KEL", "K"), "hottest cell of the estimated field"),
}
UNECE_CODES = {"SEC": 5457219, "KEL": 4932940}  # OPC UA Part 8: the code's letters as one integer
WAITING = object()  # a value of a run that has no sample yet (BadWaitingForInitialData)


def sample_values(snap: Any) -> dict[str, float | None]:
    """The numeric nodes of one snapshot (``None``: the twin does not have it)."""
    def finite(x: Any) -> float | None:
        return float(x) if x is not None and math.isfinite(float(x)) else None

    tc, tc_hat = np.asarray(snap.tc, float), np.asarray(snap.tc_hat, float)
    field = np.asarray(snap.field_hat, float)
    params = getattr(snap, "parameters", None)
    p = np.asarray(params, float) if params is not None else np.full(3, np.nan)
    sigma = getattr(snap, "sigma_mean", None)
    return {"T": finite(snap.t), "T_ref": finite(snap.T_ref), "T_mean_hat": finite(snap.T_mean_hat),
            "T_sup_hat": finite(snap.inhomogeneity), "TC4Error": finite(tc[3] - tc_hat[3]),
            "FieldSigmaMean": finite(sigma), "LampEfficiency": finite(p[0]), "Emissivity": finite(p[1]),
            "FieldMin": finite(np.nanmin(field)) if field.size else None,
            "FieldMax": finite(np.nanmax(field)) if field.size else None}


def frame_values(frame: dict[str, Any]) -> dict[str, float | None]:
    """The numeric nodes of a stream frame (the last one of an ended run: its final sample)."""
    def finite(x: Any) -> float | None:
        return float(x) if isinstance(x, int | float) and math.isfinite(float(x)) else None

    tc, tc_hat = frame.get("tc") or [None] * 4, frame.get("tc_hat") or [None] * 4
    cal = frame.get("calibration") or {}
    cells = [v for row in frame.get("field") or [] for v in row if v is not None]
    tc4 = finite(tc[3]) if len(tc) > 3 else None
    tc4_hat = finite(tc_hat[3]) if len(tc_hat) > 3 else None
    return {"T": finite(frame.get("t")), "T_ref": finite(frame.get("T_ref")),
            "T_mean_hat": finite(frame.get("T_mean_hat")), "T_sup_hat": finite(frame.get("inhomogeneity")),
            "TC4Error": None if tc4 is None or tc4_hat is None else tc4 - tc4_hat,
            "FieldSigmaMean": finite(frame.get("sigma_mean")),
            "LampEfficiency": finite((cal.get("lamp_efficiency") or {}).get("value")),
            "Emissivity": finite((cal.get("emissivity") or {}).get("value")),
            "FieldMin": min(cells) if cells else None, "FieldMax": max(cells) if cells else None}


class ResultsServer:
    """The twin's results on an OPC UA endpoint (module docstring); ``start()`` / ``stop()`` from any thread."""

    def __init__(self, manager: Any, endpoint: str, options: Any, cert_dir: str | Path) -> None:
        self.manager, self.endpoint, self.options, self.cert_dir = manager, endpoint, options, Path(cert_dir)
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="opcua-results", daemon=True)
        self._stop: asyncio.Event | None = None
        self._task: concurrent.futures.Future[None] | None = None
        self.server: Any = None
        self.nodes: dict[str, Any] = {}
        self._shown: tuple[str, int, str] | None = None  # (run id, seq, status) last published
        self._shown_run: str | None = None

    # ---- lifecycle
    def start(self, timeout: float = 30.0) -> None:
        """Serve (raises ``OSError`` / ``ValueError`` if the endpoint cannot be served)."""
        self._thread.start()
        asyncio.run_coroutine_threadsafe(self._start(), self._loop).result(timeout)
        self._task = asyncio.run_coroutine_threadsafe(self._publish_loop(), self._loop)
        log.info("the twin's results on OPC UA at %s (security %s)", self.endpoint, self.options.security)

    def stop(self) -> None:
        if self._stop is not None:
            self._loop.call_soon_threadsafe(self._stop.set)
        if self._task is not None:
            try:
                self._task.result(timeout=10)
            except Exception:
                log.debug("the results server's publishing ended", exc_info=True)
        try:
            asyncio.run_coroutine_threadsafe(self._shutdown(), self._loop).result(10)
        except Exception:
            log.debug("stopping the results server", exc_info=True)
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=10)

    async def _start(self) -> None:
        from asyncua import Server, ua

        from twin.endpoints import parse_endpoint
        from twin.furnace.opcua.security import ReadOnlyUsers, secure_server
        from twin.furnace.opcua.writes import answer_writes

        self._stop = asyncio.Event()
        server = Server(user_manager=ReadOnlyUsers())
        await server.init()
        server.set_endpoint(self.endpoint)
        server.set_server_name("furnace-twin results")
        await secure_server(server, security=self.options.security, cert_dir=self.cert_dir,
                            host=parse_endpoint(self.endpoint).host, with_users=False, role="results")
        idx = await server.register_namespace(NAMESPACE)
        node = server.nodes.objects
        for name in PATH:
            node = await node.add_object(idx, name)
        for name, (kind, unit, text) in NODES.items():
            vt = getattr(ua.VariantType, kind)
            var = await node.add_variable(idx, name, ua.Variant("" if kind == "String" else math.nan, vt),
                                          varianttype=vt)
            await var.write_attribute(ua.AttributeIds.Description,
                                      ua.DataValue(ua.Variant(ua.LocalizedText(text), ua.VariantType.LocalizedText)))
            if unit is not None:
                await var.add_property(idx, "EngineeringUnits", ua.EUInformation(
                    NamespaceUri=UNECE, UnitId=UNECE_CODES[unit[0]], DisplayName=ua.LocalizedText(unit[1]),
                    Description=ua.LocalizedText(unit[1])))
            self.nodes[name] = var
        ours = {v.nodeid: k for k, v in self.nodes.items()}
        answer_writes(server, ours.get, lambda name: False, set())
        await server.start()
        self.server = server

    async def _shutdown(self) -> None:
        if self.server is not None:
            await self.server.stop()
            self.server = None

    # ---- publishing
    async def _publish_loop(self) -> None:
        assert self._stop is not None
        while not self._stop.is_set():
            try:
                await self._publish_current()
            except Exception:
                log.exception("publishing the twin's results failed")
            try:
                await asyncio.wait_for(self._stop.wait(), timeout=POLL_S)
            except TimeoutError:
                pass

    def _current(self) -> tuple[str, int, str, dict[str, Any] | None, float] | None:
        """(run id, seq, status, its values or None, wall time of the sample) of the run to show: the newest
        this server drives that has a sample, else the newest run with its last frame (its final sample)."""
        for run_id in self.manager.live_runs():
            sample = self.manager.latest(run_id)
            if sample is not None:
                return run_id, sample.seq, sample.status, sample_values(sample.snapshot), sample.wall_time
        rows = self.manager.runs(1)
        if not rows:
            return None
        row = rows[0]
        text = self.manager.last_frame(row.id) if row.ended_at is not None else None
        if text is None:
            return row.id, -1, row.status, None, float(row.ended_at or row.created_at)
        frame = json.loads(text)
        return row.id, int(frame.get("seq", -1)), row.status, frame_values(frame), float(frame["wall_time"])

    async def _publish_current(self) -> None:
        current = await asyncio.to_thread(self._current)
        if current is None:
            return
        run_id, seq, status, sample, wall = current
        key = (run_id, seq, status)
        if key == self._shown:
            return
        self._shown = key
        from asyncua import ua

        stamp = ua.DateTime.fromtimestamp(wall, datetime.UTC)
        values: dict[str, Any] = {"RunId": run_id, "Status": status}
        if sample is not None:
            values.update(sample)
        elif self._shown_run != run_id:  # another run, no sample of it yet: none of the last one's values
            values.update(dict.fromkeys((n for n in NODES if n not in values), WAITING))
        self._shown_run = run_id
        await self._write(values, stamp)

    async def _write(self, values: dict[str, Any], stamp: Any) -> None:
        from asyncua import ua

        assert self.server is not None
        now = ua.DateTime.now(datetime.UTC)
        for name, value in values.items():
            kind = NODES[name][0]
            if value is None or value is WAITING:
                code = ua.StatusCodes.BadWaitingForInitialData if value is WAITING else ua.StatusCodes.BadNoData
                dv = ua.DataValue(ua.Variant(None, ua.VariantType.Null), StatusCode=ua.StatusCode(ua.UInt32(code)),
                                  SourceTimestamp=stamp, ServerTimestamp=now)
            else:
                dv = ua.DataValue(ua.Variant(value, getattr(ua.VariantType, kind)), SourceTimestamp=stamp,
                                  ServerTimestamp=now)
            await self.server.write_attribute_value(self.nodes[name].nodeid, dv)

