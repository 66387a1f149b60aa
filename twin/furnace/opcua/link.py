"""The asyncio side of an OPC UA furnace: connect, find the nodes, subscribe to the readings, write the inputs,
and keep the link (reconnect for a configured time, else give up).

A :class:`FurnaceLink` lives on one event loop (the OPC UA thread of
:class:`twin.furnace.opcua.furnace.OpcUaFurnace`, never the server's).  Readings are pushed to
``on_reading(channel, value, good, source_s, arrival)`` from a subscription whose trigger includes the
source timestamp, so a repeated value still counts as a new sample.  A lost link (the transport closes,
the server stops answering, a write fails for lack of a connection) is retried every
``RETRY_S`` for ``options.reconnect_s``; then the furnace is given up (:attr:`FurnaceLink.lost_reason`,
state ``down``).  The furnace may also be given up with its transport still up (:meth:`FurnaceLink.declare_lost`,
e.g. it sends no readings): writes still go through then, so the lamps can be commanded off.
"""

from __future__ import annotations

import asyncio
import datetime
import logging
import math
import time
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.furnace.opcua import messages
from twin.furnace.opcua.browse import ResolvedNode, resolve
from twin.furnace.opcua.nodes import NodeMap
from twin.furnace.opcua.options import OpcUaOptions
from twin.furnace.opcua.security import secure_client

log = logging.getLogger(__name__)

RETRY_S = 0.5  # between reconnection attempts
QUEUE_SIZE = 10  # per monitored item: readings of several samples in one publish are all kept
# The subscription publishes every 10 ms (a fifth of the default lateness margin, 0.5 t_s) and sends a keep-alive
# after 5 empty intervals (50 ms here, 0.5 s on a server with a 100 ms floor such as node-opcua), so that a
# quiet furnace (lock step while the twin plans, a stalled controller) is still heard from: asyncua recreates
# a subscription it has not heard from for 1 s.  (Interval 0, "as fast as possible", sends no keep-alive.)
PUBLISHING_INTERVAL_MS = 10.0
KEEPALIVE_COUNT = 5
ReadingSink = Callable[[int, float, bool, float, float], None]
StateSink = Callable[[str, Any, bool, float], None]  # name, value, good, source time (unix s)


class FurnaceUnavailable(ConnectionError):
    """The furnace cannot be used (unreachable, refused, lacks nodes); the message says why and what to do."""


@dataclass(frozen=True)
class LinkSettings:
    endpoint: str
    options: OpcUaOptions
    cert_dir: Path
    node_map: NodeMap
    channels: tuple[str, ...]  # the twin names read as samples, in channel order
    watched: tuple[str, ...] = ()  # twin names whose changes are reported as they come (not part of a sample)


def explain(exc: BaseException, s: LinkSettings) -> str:
    """A user's message for a failed connection or request (:func:`twin.furnace.opcua.messages.explain`)."""
    return messages.explain(exc, s.endpoint, s.options, s.cert_dir)


def _unix_s(stamp: Any) -> float | None:
    if not isinstance(stamp, datetime.datetime):
        return None
    if stamp.tzinfo is None:
        stamp = stamp.replace(tzinfo=datetime.UTC)
    return stamp.timestamp()


class _Readings:
    """The subscription handler: a data change becomes one reading of its channel, in twin units (or, for a
    watched node, a state change)."""

    def __init__(self, channel_of: Mapping[Any, int], specs: Sequence[Any], sink: ReadingSink,
                 watched: Mapping[Any, str] | None = None, state_sink: StateSink | None = None) -> None:
        self.channel_of, self.specs, self.sink = channel_of, specs, sink
        self.watched, self.state_sink = dict(watched or {}), state_sink

    def datachange_notification(self, node: Any, val: Any, data: Any) -> None:
        ch = self.channel_of.get(node.nodeid)
        dv = data.monitored_item.Value
        good = dv.StatusCode is None or dv.StatusCode.is_good()
        if ch is None:
            name = self.watched.get(node.nodeid)
            if name is not None and self.state_sink is not None:
                stamp = _unix_s(dv.SourceTimestamp) or _unix_s(dv.ServerTimestamp) or time.time()
                self.state_sink(name, val, good, stamp)
            return
        try:
            value = self.specs[ch].to_twin(float(val)) if good and val is not None else math.nan
        except (TypeError, ValueError):
            value, good = math.nan, False
        source = _unix_s(dv.SourceTimestamp) or _unix_s(dv.ServerTimestamp) or time.time()
        self.sink(ch, value, good, source, time.monotonic())

    def status_change_notification(self, status: Any) -> None:
        log.warning("furnace subscription status: %s", status)


class FurnaceLink:
    """One furnace over OPC UA, on the current event loop."""

    def __init__(self, settings: LinkSettings, on_reading: ReadingSink, on_state: StateSink | None = None) -> None:
        self.s = settings
        self._on_reading = on_reading
        self._on_state = on_state
        self._client: Any = None
        self.nodes: dict[str, ResolvedNode] = {}
        self.state = "new"  # the transport: new, connected, reconnecting, down (not restored), closed
        self.connected_since = -math.inf  # monotonic s of the latest (re)connection
        self.connection_began = -math.inf  # monotonic s at which the attempt that made it began (readings that
        # arrived since then came over it: its subscription can deliver before the attempt returns)
        self.lost_reason: str | None = None  # set when the furnace is given up
        self.events: deque[str] = deque()  # for the run's event log (read from another thread)
        self._reconnect_task: asyncio.Task[None] | None = None

    # ---- connecting
    async def _connect_once(self, lost_since: float | None = None) -> None:
        from asyncua import Client, ua

        o = self.s.options
        began = time.monotonic()
        client = Client(self.s.endpoint, timeout=o.connect_timeout_s, watchdog_intervall=1.0)
        await secure_client(client, security=o.security, cert_dir=self.s.cert_dir, username=o.username,
                            password=o.secret())
        try:
            await asyncio.wait_for(client.connect(), timeout=o.connect_timeout_s)
        except Exception as exc:
            refused = getattr(client.certificate_validator, "refused", None)  # this twin refused the server's
            if refused is not None:
                raise messages.UntrustedServer(*refused) from exc
            raise
        try:
            nodes = await resolve(client, self.s.node_map)
            channel_of = {nodes[name].node.nodeid: i for i, name in enumerate(self.s.channels)}
            specs = [self.s.node_map.nodes[name] for name in self.s.channels]
            watched = {nodes[name].node.nodeid: name for name in self.s.watched if name in nodes}
            params = ua.CreateSubscriptionParameters(RequestedPublishingInterval=PUBLISHING_INTERVAL_MS,
                                                     RequestedLifetimeCount=KEEPALIVE_COUNT * 30,
                                                     RequestedMaxKeepAliveCount=KEEPALIVE_COUNT,
                                                     MaxNotificationsPerPublish=0, PublishingEnabled=True,
                                                     Priority=0)
            sub = await client.create_subscription(params, _Readings(channel_of, specs, self._on_reading, watched,
                                                                     self._on_state))
            trigger = ua.DataChangeFilter(Trigger=ua.DataChangeTrigger.StatusValueTimestamp)
            monitored = [*self.s.channels, *(name for name in self.s.watched if name in nodes)]
            requests = [ua.MonitoredItemCreateRequest(
                ItemToMonitor=ua.ReadValueId(NodeId=nodes[name].node.nodeid, AttributeId=ua.AttributeIds.Value),
                MonitoringMode=ua.MonitoringMode.Reporting,
                RequestedParameters=ua.MonitoringParameters(ClientHandle=10_000 + i, SamplingInterval=0.0,
                                                            QueueSize=QUEUE_SIZE, DiscardOldest=True,
                                                            Filter=trigger))
                for i, name in enumerate(monitored)]
            for result in await sub.create_monitored_items(requests):
                if isinstance(result, ua.StatusCode):
                    result.check()
        except BaseException:
            await self._drop(client)
            raise
        client.connection_lost_callback = self._lost
        if lost_since is not None:  # a reconnection: its event queued before the state says "connected", so a
            # reader who sees the link connected finds the event too (the test saw one without the other)
            msg = f"link to the furnace restored after {time.monotonic() - lost_since:.1f} s"
            log.info(msg)
            self.events.append(msg)
        self._client, self.nodes, self.state = client, nodes, "connected"
        self.connection_began, self.connected_since = began, time.monotonic()

    async def open(self) -> None:
        """The first connection; :class:`FurnaceUnavailable` with a message if it fails."""
        try:
            await self._connect_once()
        except Exception as exc:
            raise FurnaceUnavailable(explain(exc, self.s)) from exc
        log.info("connected to the furnace at %s (security %s)", self.s.endpoint, self.s.options.security)

    @staticmethod
    async def _drop(client: Any) -> None:
        try:
            await asyncio.wait_for(client.disconnect(), timeout=1.0)
        except Exception:
            try:
                client.disconnect_socket()
            except Exception:
                log.debug("dropping an OPC UA client", exc_info=True)

    # ---- keeping the link
    @property
    def lost(self) -> bool:
        """The furnace is given up (the run ends ``plant_lost``)."""
        return self.lost_reason is not None

    async def _lost(self, exc: BaseException) -> None:
        if self.state != "connected" or self.lost:
            return
        self.state = "reconnecting"
        msg = (f"link to the furnace lost ({explain(exc, self.s)}); reconnecting for up to "
               f"{self.s.options.reconnect_s:g} s")
        log.warning(msg)
        self.events.append(msg)
        self._reconnect_task = asyncio.get_running_loop().create_task(self._reconnect(time.monotonic()))

    async def _reconnect(self, since: float) -> None:
        client, self._client = self._client, None
        if client is not None:
            await self._drop(client)
        deadline = since + self.s.options.reconnect_s
        last: BaseException | None = None
        while self.state == "reconnecting":
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                break
            try:
                await asyncio.wait_for(self._connect_once(since), timeout=max(remaining, 0.1))
            except Exception as exc:
                last = exc
                await asyncio.sleep(min(RETRY_S, max(deadline - time.monotonic(), 0.0)))
                continue
            return
        if self.state == "reconnecting":
            why = explain(last, self.s) if last is not None else "no attempt succeeded"
            self.state = "down"
            self.declare_lost(f"the link to the furnace was lost and not restored within "
                              f"{self.s.options.reconnect_s:g} s ({why})")

    def declare_lost(self, reason: str) -> None:
        """Give the furnace up (the run then ends ``plant_lost``); the transport stays as it is."""
        if self.lost or self.state == "closed":
            return
        self.lost_reason = reason
        log.error(reason)
        self.events.append(reason)

    # ---- requests
    def _variant(self, name: str, value: Any) -> Any:
        from asyncua import ua

        vt = self.nodes[name].variant_type
        if vt == ua.VariantType.Boolean:
            return ua.Variant(bool(value), vt)
        if vt in (ua.VariantType.Double, ua.VariantType.Float):
            return ua.Variant(float(self.s.node_map.nodes[name].to_furnace(float(value))), vt)
        return ua.Variant(int(round(self.s.node_map.nodes[name].to_furnace(float(value)))), vt)

    async def write(self, values: Mapping[str, Any]) -> None:
        """One Write request for all ``values`` (twin units); a lost transport starts the reconnection."""
        from asyncua import ua

        client = self._client
        if self.state != "connected" or client is None:
            raise ConnectionError(f"the link to the furnace is {self.state}")
        names = list(values)
        try:
            # values without timestamps: asyncua stamps a bare value with the client's clock, which a server may
            # refuse (open62541: BadWriteNotSupported) and which is not the twin's to say for a setpoint
            await client.write_values([self.nodes[n].node for n in names],
                                      [ua.DataValue(self._variant(n, values[n])) for n in names])
        except (ConnectionError, OSError, TimeoutError) as exc:
            await self._lost(exc)
            raise

    async def read(self, names: Sequence[str]) -> dict[str, Any]:
        client = self._client
        if self.state != "connected" or client is None:
            raise ConnectionError(f"the link to the furnace is {self.state}")
        values = await client.read_values([self.nodes[n].node for n in names])
        return dict(zip(names, values, strict=True))

    async def close(self) -> None:
        self.state = "closed"
        if self._reconnect_task is not None:
            self._reconnect_task.cancel()
        client, self._client = self._client, None
        if client is not None:
            await self._drop(client)
