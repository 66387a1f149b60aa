"""``furnace-twin opcua-check ENDPOINT [--mapping F] [--json]``: what an integrator runs first at a furnace.

It connects as the twin would (``FURNACE_TWIN_OPCUA_*``: security, user, the mapping file unless ``--mapping``
says another; certificates in ``<data dir>/opcua``), looks up every node the twin needs (product.md's address
space, or where the mapping says: browse paths, ``ns=`` and ``nsu=`` NodeIds resolved through the server's
namespace array), and prints for each one its NodeId (also as ``nsu=``, which does not depend on the server's
numbering), data type, access for this session, the value now with its status and whether it carries a
source timestamp, and what would stop the twin using it.  It writes nothing: no watchdog, no setpoint.

What the twin needs of each node (:data:`NEEDS`): TC1..TC4 and ``Eta`` numbers it can read, the lamp-group
setpoints, ``Amplitude`` and ``Period`` numbers it can write, ``OscillationEnabled`` a Boolean it can write,
``Watchdog`` an integer it can write (a counter: it wraps at the type's range), ``LampsEnabled`` a Boolean it
can read.  Exit status 0: every node usable; 1: some are not (each one says why), or there is no furnace object;
2: the furnace cannot be reached (or refuses this twin) or the arguments are wrong.

Example
-------
>>> need = needs(("T1h",))
>>> problem("Double", {"read"}, need["TC1"]), problem("Double", {"read"}, need["T1h"])
(None, 'not writable for this session')
>>> problem("Double", {"read", "write"}, need["Watchdog"]), problem("Boolean", {"read"}, need["LampsEnabled"])
('Double is not an integer type (the twin increments it)', None)
"""

from __future__ import annotations

import argparse
import asyncio
import json
import sys
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

from twin.config import FurnaceConfig
from twin.furnace.opcua import nodes as names

NUMBERS = ("Double", "Float", "SByte", "Byte", "Int16", "UInt16", "Int32", "UInt32", "Int64", "UInt64")
INTEGERS = NUMBERS[2:]


@dataclass(frozen=True)
class Need:
    kind: str  # "number", "integer" or "boolean"
    access: str  # "read" or "write"


def needs(group_names: tuple[str, ...]) -> dict[str, Need]:
    """What the twin does with each node (module docstring)."""
    out = {tc: Need("number", "read") for tc in names.TC_NAMES}
    out.update({g: Need("number", "write") for g in group_names})
    out.update({names.ETA: Need("number", "read"), names.OSCILLATION_ENABLED: Need("boolean", "write"),
                names.AMPLITUDE: Need("number", "write"), names.PERIOD: Need("number", "write"),
                names.WATCHDOG: Need("integer", "write"), names.LAMPS_ENABLED: Need("boolean", "read")})
    return out


def problem(data_type: str, access: set[str], need: Need | None) -> str | None:
    """Why the twin could not use a node of this type and access for what it ``need``s (``None``: it can)."""
    if need is None:
        return None
    if need.kind == "boolean" and data_type != "Boolean":
        return f"{data_type} is not a Boolean"
    if need.kind == "number" and data_type not in NUMBERS:
        return f"{data_type} is not a number"
    if need.kind == "integer" and data_type not in INTEGERS:
        return f"{data_type} is not an integer type (the twin increments it)"
    if need.access not in access:
        return "not writable for this session" if need.access == "write" else "not readable for this session"
    return None


@dataclass(frozen=True)
class NodeReport:
    """One node as found on the server."""

    name: str
    where: str  # where the twin looks for it (mapping)
    node_id: str | None = None
    nsu_node_id: str | None = None
    data_type: str | None = None
    access: str | None = None  # "read", "read/write", ...
    value: Any = None
    status: str | None = None
    source_timestamp: bool | None = None
    problem: str | None = None


def _nsu(node_id: Any, namespaces: list[str]) -> str:
    text = node_id.to_string()
    ns = int(node_id.NamespaceIndex)
    if ns == 0 or ns >= len(namespaces):
        return str(text)
    return f"nsu={namespaces[ns]};" + str(text).split(";", 1)[1]


async def _report(name: str, where: str, node: Any, data_type: Any, need: Need | None,
                  namespaces: list[str]) -> NodeReport:
    from asyncua import ua

    levels = await node.get_user_access_level()
    access = {a for a, bit in (("read", ua.AccessLevel.CurrentRead), ("write", ua.AccessLevel.CurrentWrite))
              if bit in levels}
    value = status = stamped = None
    if "read" in access:
        dv = await node.read_data_value(raise_on_bad_status=False)
        value = dv.Value.Value if dv.Value is not None else None
        status = ua.status_codes.get_name_and_doc(dv.StatusCode.value)[0] if dv.StatusCode is not None else "Good"
        stamped = dv.SourceTimestamp is not None
        if isinstance(value, float | int | bool | str) or value is None:
            pass
        else:
            value = str(value)
    type_name = data_type.name
    return NodeReport(name, where, node.nodeid.to_string(), _nsu(node.nodeid, namespaces), type_name,
                      "/".join(a for a in ("read", "write") if a in access) or "none", value, status, stamped,
                      problem(type_name, access, need))


async def inspect_furnace(endpoint: str, options: Any, cert_dir: Path, node_map: Any) -> dict[str, Any]:
    """Connect, look up every node of ``node_map`` and report on each (module docstring); writes nothing."""
    from asyncua import Client

    from twin.furnace.opcua.browse import ResolvedNode, locate
    from twin.furnace.opcua.security import secure_client

    client = Client(endpoint, timeout=options.connect_timeout_s)
    await secure_client(client, security=options.security, cert_dir=cert_dir, username=options.username,
                        password=options.secret())
    await asyncio.wait_for(client.connect(), timeout=options.connect_timeout_s)
    try:
        namespaces = list(await client.get_namespace_array())
        located = await locate(client, node_map)
        wanted = needs(node_map.group_names)
        reports = []
        for name in [*node_map.nodes, *(n for n in located if n not in node_map.nodes)]:
            got = located.get(name)
            where = node_map.describe(name) if name in node_map.nodes else f"{name} (optional)"
            if isinstance(got, ResolvedNode):
                reports.append(await _report(name, where, got.node, got.variant_type, wanted.get(name), namespaces))
            else:
                reports.append(NodeReport(name, where, problem=f"not found: {got}"))
    finally:
        await client.disconnect()
    return {"endpoint": endpoint, "security": options.security, "mapping": node_map.source,
            "namespaces": namespaces, "nodes": [asdict(r) for r in reports],
            "ok": all(r.problem is None for r in reports)}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("endpoint", help="opc.tcp://host:port/path of the furnace's OPC UA server")
    p.add_argument("--mapping", default=None, help="a mapping file (default: $FURNACE_TWIN_OPCUA_MAPPING, else "
                                                   "product.md's address space)")
    p.add_argument("--json", action="store_true", help="print one JSON object instead of the table")


def _table(result: dict[str, Any]) -> str:
    rows = [("node", "NodeId", "type", "access", "value", "status", "problem")]
    for r in result["nodes"]:
        value = "" if r["value"] is None else (f"{r['value']:.6g}" if isinstance(r["value"], float) else
                                               str(r["value"]))
        stamp = "" if r["source_timestamp"] in (None, True) else " (no source timestamp)"
        rows.append((r["name"], r["nsu_node_id"] or "-", r["data_type"] or "-", r["access"] or "-", value,
                     (r["status"] or "-") + stamp, r["problem"] or "ok"))
    widths = [max(len(row[i]) for row in rows) for i in range(len(rows[0]) - 1)]
    lines = ["  ".join(c.ljust(w) for c, w in zip(row[:-1], widths, strict=True)) + "  " + row[-1] for row in rows]
    verdict = "every node the twin needs is there and usable" if result["ok"] else \
        "the twin cannot use this furnace as it is: see the nodes whose problem is not 'ok'"
    return "\n".join([f"{result['endpoint']} (security {result['security']}, mapping {result['mapping']})",
                      "namespaces: " + ", ".join(f"{i}={u}" for i, u in enumerate(result["namespaces"])),
                      *lines, verdict])


def check_command(cfg: FurnaceConfig, args: Any) -> int:
    """``furnace-twin opcua-check``: 0 usable, 1 not, 2 cannot connect / bad arguments."""
    import os

    from pydantic import ValidationError

    from twin.endpoints import parse_endpoint
    from twin.furnace.opcua.browse import MissingNodes
    from twin.furnace.opcua.messages import explain
    from twin.furnace.opcua.nodes import MappingError, load_mapping
    from twin.furnace.opcua.options import OpcUaOptions, certificate_dir

    try:
        parse_endpoint(args.endpoint)
        options = OpcUaOptions()
        node_map = load_mapping(args.mapping or options.mapping, [g.name for g in cfg.lamps.groups])
    except (ValueError, MappingError, ValidationError) as exc:
        print(f"furnace-twin opcua-check: {exc}", file=sys.stderr)  # noqa: T201
        return 2
    cert_dir = certificate_dir(os.environ.get("FURNACE_TWIN_DATA_DIR", "furnace-data"))
    try:
        result = asyncio.run(inspect_furnace(args.endpoint, options, cert_dir, node_map))
    except Exception as exc:  # unreachable, refused, or no furnace object: one sentence
        print(f"furnace-twin opcua-check: {explain(exc, args.endpoint, options, cert_dir)}", file=sys.stderr)  # noqa: T201
        return 1 if isinstance(exc, MissingNodes) else 2
    print(json.dumps(result, default=str) if args.json else _table(result))  # noqa: T201
    return 0 if result["ok"] else 1
