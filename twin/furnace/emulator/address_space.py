"""The emulator's OPC UA address space, built from a :class:`twin.furnace.opcua.nodes.NodeMap` (product.md's
by default, or the one a mapping file describes, so the twin's mapping can be tried against it).

Written values pass through setters: lamp-group setpoints are clamped to 0..1 (in twin units; a furnace
unit from the mapping's scale and offset), the drive's amplitude to 0..eta_max and its period to
1..600 s; a new watchdog value goes to the interlock.  TCs, ``Eta``, ``LampsEnabled`` and ``LockStep`` are
read-only.  What a client is told about its write (:mod:`twin.furnace.opcua.writes`): ``GoodClamped`` when a
value was clamped, ``BadNotWritable`` for a read-only node; a value written with a Bad status is ignored (a watchdog
written Bad does not count as a sign of life, a setpoint written Bad switches its group off).

A NodeId of the map may name its namespace by URI (``nsu=urn:lab:annealer;s=TE101``): the emulator
registers that namespace and serves the node there, as a third-party server would.
"""

from __future__ import annotations

import datetime
import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from twin.furnace.emulator.interlock import clamp_setpoint
from twin.furnace.opcua import nodes as names
from twin.furnace.opcua.nodes import NodeMap, NodeSpec
from twin.furnace.opcua.writes import answer_writes
from twin.scenario import OscillationSpec

log = logging.getLogger(__name__)

NAMESPACE = "urn:furnace-twin:emulator"
PERIOD_RANGE_S = (1.0, 600.0)  # the drive's period limits (twin.scenario.OscillationSpec)


@dataclass(frozen=True)
class Kind:
    variant: str  # asyncua VariantType name
    writable: bool
    initial: Any


def node_kinds(node_map: NodeMap, T0: float, drive: OscillationSpec) -> dict[str, Kind]:
    """Each node's type, access and first value (TCs at T0 K, the drive as ``drive``, lamps off)."""
    kinds = {tc: Kind("Double", False, T0) for tc in names.TC_NAMES}
    kinds.update({g: Kind("Double", True, 0.0) for g in node_map.group_names})
    kinds.update({names.ETA: Kind("Double", False, 0.0),
                  names.OSCILLATION_ENABLED: Kind("Boolean", True, drive.enabled),
                  names.AMPLITUDE: Kind("Double", True, drive.amplitude),
                  names.PERIOD: Kind("Double", True, drive.period),
                  names.WATCHDOG: Kind("UInt32", True, 0), names.LAMPS_ENABLED: Kind("Boolean", False, False)})
    return kinds


def utc_now() -> Any:
    """Now, as an OPC UA DateTime (UTC)."""
    from asyncua import ua

    return ua.DateTime.now(datetime.UTC)


def _furnace_value(spec: NodeSpec, kind: Kind, twin_value: Any) -> Any:
    if kind.variant == "Double":
        return float(spec.to_furnace(float(twin_value)))
    return twin_value


class AddressSpace:
    """The nodes of one emulated furnace on an ``asyncua.Server``; values read and written in twin units."""

    def __init__(self, server: Any, node_map: NodeMap, *, eta_max: float,
                 on_watchdog: Callable[[int], None]) -> None:
        self.server, self.map, self.eta_max = server, node_map, float(eta_max)
        self.on_watchdog = on_watchdog
        self.nodes: dict[str, Any] = {}
        self.kinds: dict[str, Kind] = {}
        self._names: dict[Any, str] = {}  # NodeId -> twin name
        self._clamped: set[Any] = set()  # NodeIds whose value the write being served clamped

    async def _namespace(self, index_needed: int | None = None) -> int:
        uri = self.map.namespace or NAMESPACE
        idx = int(await self.server.register_namespace(uri))
        while index_needed is not None and index_needed > len(await self.server.get_namespace_array()) - 1:
            await self.server.register_namespace(f"{NAMESPACE}:ns{len(await self.server.get_namespace_array())}")
        return idx

    async def _node_id(self, text: str) -> Any:
        """The NodeId a map entry names; a namespace given by URI (``nsu=``) is registered and used by index."""
        from asyncua import ua

        parsed = ua.NodeId.from_string(text)
        uri = getattr(parsed, "NamespaceUri", None)
        if uri:
            idx = int(await self.server.register_namespace(uri))
            return ua.NodeId(parsed.Identifier, ua.Int16(idx), parsed.NodeIdType)
        await self._namespace(parsed.NamespaceIndex)
        return ua.NodeId(parsed.Identifier, parsed.NamespaceIndex, parsed.NodeIdType)

    async def _object(self, parent: Any, path: tuple[str, ...], idx: int) -> Any:
        from asyncua import ua

        node = parent
        for name in path:
            found = None
            for ch in await node.get_children(refs=ua.ObjectIds.HierarchicalReferences):
                if (await ch.read_browse_name()).Name == name:
                    found = ch
                    break
            node = found if found is not None else await node.add_object(idx, name)
        return node

    async def build(self, T0: float, drive: OscillationSpec, *, lock_step: bool = False) -> None:
        """Create every node of the map (T0: the TCs' first value, K; ``drive``: the drive's settings) and the
        emulator's own ``LockStep`` (Boolean, read-only: the furnace's clock advances only on the client's writes)."""
        from asyncua import ua

        idx = await self._namespace()
        furnace = await self._object(self.server.nodes.objects, self.map.object_path, idx)
        self.kinds = node_kinds(self.map, T0, drive)
        for name, spec in self.map.nodes.items():
            kind = self.kinds[name]
            vt = getattr(ua.VariantType, kind.variant)
            value = ua.Variant(_furnace_value(spec, kind, kind.initial), vt)
            if spec.node_id is not None:
                nodeid = await self._node_id(spec.node_id)
                node = await furnace.add_variable(nodeid, ua.QualifiedName(name, nodeid.NamespaceIndex), value,
                                                  varianttype=vt)
            else:
                path = spec.path or (name,)
                parent = await self._object(furnace, path[:-1], idx)
                node = await parent.add_variable(idx, path[-1], value, varianttype=vt)
            if kind.writable:
                await node.set_writable()
                self.server.set_attribute_value_setter(node.nodeid, self._setter(name))
            self.nodes[name] = node
            self._names[node.nodeid] = name
        self.nodes[names.LOCK_STEP] = await furnace.add_variable(idx, names.LOCK_STEP, bool(lock_step),
                                                                 varianttype=ua.VariantType.Boolean)
        self._names[self.nodes[names.LOCK_STEP].nodeid] = names.LOCK_STEP
        answer_writes(self.server, self._names.get, self._writable, self._clamped)

    def _writable(self, name: str) -> bool:
        kind = self.kinds.get(name)
        return kind is not None and kind.writable

    def _setter(self, name: str) -> Callable[[Any, Any, Any], None]:
        from asyncua import ua

        spec, kind = self.map.nodes[name], self.kinds[name]

        def store(node: Any, attr: Any, dv: Any) -> None:
            raw: Any = dv.Value.Value if dv.Value is not None else None
            bad = (dv.StatusCode is not None and not dv.StatusCode.is_good()) or raw is None
            if name == names.WATCHDOG:
                if bad:  # no sign of life: the interlock keeps its time
                    log.warning("watchdog written with status %s: ignored", dv.StatusCode)
                    return
                value: Any = int(raw)
                self.on_watchdog(value)
            elif kind.variant == "Boolean":
                value = bool(raw) if not bad else False
            else:
                twin = spec.to_twin(float(raw)) if not bad else math.nan
                limited = self._limit(name, twin)
                if math.isfinite(twin) and limited != twin:
                    self._clamped.add(node.nodeid)
                value = spec.to_furnace(limited)
            node.attributes[attr].value = ua.DataValue(ua.Variant(value, getattr(ua.VariantType, kind.variant)),
                                                       SourceTimestamp=utc_now(), ServerTimestamp=utc_now())

        return store

    def _limit(self, name: str, value: float) -> float:
        """Clamp a written number (twin units) to what the furnace accepts; logged when it bites."""
        if name == names.AMPLITUDE:
            lo, hi = 0.0, self.eta_max
        elif name == names.PERIOD:
            lo, hi = PERIOD_RANGE_S
        else:
            return clamp_setpoint(value)
        limited = min(max(value, lo), hi) if math.isfinite(value) else lo
        if limited != value:
            log.warning("%s = %r clamped to %g", name, value, limited)
        return limited

    # ---- values in twin units
    def value(self, name: str) -> Any:
        dv = self.server.read_attribute_value(self.nodes[name].nodeid)
        raw = dv.Value.Value if dv.Value is not None else None
        if self.kinds[name].variant == "Double":
            return self.map.nodes[name].to_twin(float(raw)) if raw is not None else math.nan
        return raw

    async def publish(self, values: dict[str, tuple[Any, bool]], stamp: Any) -> None:
        """Write (value, good) per name with this source timestamp (:func:`utc_now`); a bad value is published
        with status Bad."""
        from asyncua import ua

        now = utc_now()
        for name, (v, good) in values.items():
            kind = self.kinds[name]
            if good:
                dv = ua.DataValue(ua.Variant(_furnace_value(self.map.nodes[name], kind, v),
                                             getattr(ua.VariantType, kind.variant)),
                                  SourceTimestamp=stamp, ServerTimestamp=now)
            else:
                dv = ua.DataValue(ua.Variant(None, ua.VariantType.Null),
                                  StatusCode=ua.StatusCode(ua.UInt32(ua.StatusCodes.BadSensorFailure)),
                                  SourceTimestamp=stamp, ServerTimestamp=now)
            await self.server.write_attribute_value(self.nodes[name].nodeid, dv)
