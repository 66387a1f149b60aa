"""The OPC UA address space the twin expects of a furnace (product.md), and the mapping file for a furnace
whose node names differ.

The default address space (what ``furnace-twin emulate`` serves): an object ``Furnace`` under Objects
holding ``TC1``..``TC4`` (Double, K, source timestamps; status Bad while a TC is dropped), an object
``LampGroups`` with one Double setpoint per lamp group (``T1h`` ... ``T2v``: fractions 0..1, writable,
clamped), ``Eta`` (Double, m), ``OscillationEnabled`` (Boolean), ``Amplitude`` (m) and ``Period`` (s)
(writable), ``Watchdog`` (UInt32 the client increments every sample) and ``LampsEnabled`` (Boolean,
the interlock state).  Browse names are matched by name (any namespace, unless the mapping names one).

A mapping file (TOML) says where each of these lives on another furnace, and in which units:

.. code-block:: toml

    object = "Plant/Annealer"            # browse path from Objects to the furnace object
    namespace = "urn:lab:annealer"       # optional: match browse names in this namespace only
    [nodes]
    TC1 = "Sensors/TE101"                # browse path below the furnace object
    TC2 = {node = "ns=3;s=TE102", offset = -273.15}   # a NodeId; the furnace reports deg C
    T1h = {node = "Heating/Zone1", scale = 100.0}     # the furnace takes percent

A node's furnace value is ``scale * twin value + offset`` (twin units: K, fractions of u_max, m, s).
Names left out keep their default place.

Example
-------
>>> m = NodeMap.default(("T1h", "T2h"))
>>> m.nodes["TC1"].path, m.nodes["T2h"].path, m.object_path
(('TC1',), ('LampGroups', 'T2h'), ('Furnace',))
>>> spec = NodeSpec(path=("TC",), scale=1.0, offset=-273.15)
>>> spec.to_furnace(1100.0), spec.to_twin(826.85)
(826.85, 1100.0)
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

TC_NAMES = ("TC1", "TC2", "TC3", "TC4")
ETA, OSCILLATION_ENABLED, AMPLITUDE, PERIOD = "Eta", "OscillationEnabled", "Amplitude", "Period"
WATCHDOG, LAMPS_ENABLED = "Watchdog", "LampsEnabled"
#: optional, the emulator's own (``furnace-twin emulate --lock-step``): true when the furnace's clock advances
#: one sample per watchdog value the client writes, instead of in real time
LOCK_STEP = "LockStep"
LAMP_GROUPS_OBJECT = "LampGroups"
FURNACE_OBJECT = "Furnace"

#: twin names whose values are numbers in twin units (K, fractions, m, s): these may carry scale / offset
_SCALABLE_FIXED = (*TC_NAMES, ETA, AMPLITUDE, PERIOD)
_NODE_ID_PREFIXES = ("ns=", "i=", "s=", "g=", "b=", "nsu=")


class MappingError(ValueError):
    """A mapping file is unreadable or says something the twin cannot use; the message names the entry."""


@dataclass(frozen=True)
class NodeSpec:
    """Where one twin quantity lives: a browse path below the furnace object, or a NodeId string.

    ``scale`` and ``offset`` convert twin units to the furnace's: furnace = scale * twin + offset.
    """

    path: tuple[str, ...] | None = None
    node_id: str | None = None
    scale: float = 1.0
    offset: float = 0.0

    def to_furnace(self, value: float) -> float:
        return self.scale * value + self.offset

    def to_twin(self, value: float) -> float:
        return (value - self.offset) / self.scale

    def describe(self) -> str:
        return self.node_id if self.node_id is not None else "/".join(self.path or ())


@dataclass(frozen=True)
class NodeMap:
    """Every node the twin reads or writes, by twin name (TC1..TC4, the lamp groups, Eta, ...)."""

    object_path: tuple[str, ...]
    nodes: dict[str, NodeSpec]
    group_names: tuple[str, ...]
    namespace: str | None = None
    source: str = "default"  # the mapping file, for messages
    scalable: frozenset[str] = field(default_factory=frozenset)

    @classmethod
    def default(cls, group_names: Sequence[str]) -> NodeMap:
        """The address space of product.md for a furnace with these lamp groups."""
        groups = tuple(group_names)
        nodes = {name: NodeSpec(path=(name,)) for name in
                 (*TC_NAMES, ETA, OSCILLATION_ENABLED, AMPLITUDE, PERIOD, WATCHDOG, LAMPS_ENABLED)}
        nodes.update({g: NodeSpec(path=(LAMP_GROUPS_OBJECT, g)) for g in groups})
        return cls(object_path=(FURNACE_OBJECT,), nodes=nodes, group_names=groups,
                   scalable=frozenset((*_SCALABLE_FIXED, *groups)))

    def describe(self, name: str) -> str:
        """``name`` and where it is looked up, for messages."""
        return f"{name} ({'/'.join(self.object_path)}/{self.nodes[name].describe()}, mapping: {self.source})"


def _split_path(text: str, where: str) -> tuple[str, ...]:
    parts = tuple(p.strip() for p in text.strip().strip("/").split("/"))
    if not text.strip() or any(not p for p in parts):
        raise MappingError(f"{where}: {text!r} is not a browse path (names separated by '/')")
    return parts


def _node_spec(name: str, entry: Any, where: str, scalable: bool) -> NodeSpec:
    if isinstance(entry, str):
        entry = {"node": entry}
    if not isinstance(entry, Mapping):
        raise MappingError(f"{where}: expected a browse path, a NodeId or a table {{node = ..., scale, offset}}")
    unknown = set(entry) - {"node", "scale", "offset"}
    if unknown:
        raise MappingError(f"{where}: unknown keys {sorted(unknown)} (allowed: node, scale, offset)")
    node = entry.get("node")
    if not isinstance(node, str) or not node.strip():
        raise MappingError(f"{where}: 'node' must be a browse path or a NodeId string")
    try:
        scale, offset = float(entry.get("scale", 1.0)), float(entry.get("offset", 0.0))
    except (TypeError, ValueError):
        raise MappingError(f"{where}: scale and offset must be numbers") from None
    if not (math.isfinite(scale) and math.isfinite(offset)) or scale == 0.0:
        raise MappingError(f"{where}: scale must be finite and non-zero, offset finite")
    if (scale, offset) != (1.0, 0.0) and not scalable:
        raise MappingError(f"{where}: {name} is not a number in twin units; it takes no scale or offset")
    node = node.strip()
    if node.startswith(_NODE_ID_PREFIXES):
        return NodeSpec(node_id=node, scale=scale, offset=offset)
    return NodeSpec(path=_split_path(node, where), scale=scale, offset=offset)


def mapping_from_dict(data: Mapping[str, Any], group_names: Sequence[str], source: str = "<dict>") -> NodeMap:
    """A :class:`NodeMap` from a parsed mapping file (see the module docstring)."""
    base = NodeMap.default(group_names)
    unknown = set(data) - {"object", "namespace", "nodes"}
    if unknown:
        raise MappingError(f"{source}: unknown keys {sorted(unknown)} (allowed: object, namespace, nodes)")
    obj = data.get("object", FURNACE_OBJECT)
    if not isinstance(obj, str):
        raise MappingError(f"{source}: object must be a browse path string")
    namespace = data.get("namespace")
    if namespace is not None and (not isinstance(namespace, str) or not namespace):
        raise MappingError(f"{source}: namespace must be a namespace URI string")
    entries = data.get("nodes", {})
    if not isinstance(entries, Mapping):
        raise MappingError(f"{source}: [nodes] must be a table of twin name = node")
    unknown_names = sorted(set(entries) - set(base.nodes))
    if unknown_names:
        raise MappingError(f"{source}: [nodes] has unknown names {unknown_names}; the twin's names are "
                           f"{', '.join(base.nodes)}")
    nodes = dict(base.nodes)
    for name, entry in entries.items():
        nodes[name] = _node_spec(name, entry, f"{source}: nodes.{name}", name in base.scalable)
    return replace(base, object_path=_split_path(obj, f"{source}: object"), nodes=nodes, namespace=namespace,
                   source=source)


def load_mapping(path: str | Path | None, group_names: Sequence[str]) -> NodeMap:
    """The mapping file at ``path`` (``None``: the default address space); :class:`MappingError` if unusable."""
    if path is None:
        return NodeMap.default(group_names)
    p = Path(path)
    try:
        data = tomllib.loads(p.read_text())
    except OSError as exc:
        raise MappingError(f"cannot read the OPC UA mapping file {p}: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise MappingError(f"the OPC UA mapping file {p} is not valid TOML: {exc}") from None
    return mapping_from_dict(data, group_names, source=str(p))
