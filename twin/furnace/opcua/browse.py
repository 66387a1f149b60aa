"""Find a furnace's nodes on an OPC UA server: browse paths by browse name (or NodeIds) of a :class:`NodeMap`.

:func:`resolve` returns every node of the map with the variant type its value is written with; a node the
server does not have is a :class:`MissingNodes` error that names each one and where it was looked for.
A NodeId that names its namespace by URI (``nsu=urn:lab:annealer;s=TE101``) is resolved through the
server's namespace array at every connection (a server may number its namespaces differently after a
restart); a URI the server does not have is named in the error.  Optional nodes (the emulator's
``LockStep``) are looked for below the furnace object and left out when absent.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from twin.furnace.opcua.nodes import LOCK_STEP, NodeMap

OPTIONAL = (LOCK_STEP,)  # looked for below the furnace object, not required


class MissingNodes(LookupError):
    """The server lacks nodes the twin needs (the message lists them)."""


@dataclass(frozen=True)
class ResolvedNode:
    node: Any  # asyncua Node
    variant_type: Any  # asyncua ua.VariantType of its value


async def _namespace_index(client: Any, uri: str | None) -> int | None:
    if uri is None:
        return None
    array = await client.get_namespace_array()
    if uri not in array:
        raise MissingNodes(f"the server has no namespace {uri!r} (it has {', '.join(array)})")
    return int(array.index(uri))


class _Browser:
    """Children by browse name, each level browsed once."""

    def __init__(self, ns: int | None) -> None:
        self.ns = ns
        self._children: dict[Any, dict[str, Any]] = {}

    async def child(self, parent: Any, name: str) -> Any | None:
        if parent.nodeid not in self._children:
            named: dict[str, Any] = {}
            for ch in await parent.get_children():
                qn = await ch.read_browse_name()
                if self.ns is None or qn.NamespaceIndex == self.ns:
                    named.setdefault(qn.Name, ch)
            self._children[parent.nodeid] = named
        return self._children[parent.nodeid].get(name)

    async def walk(self, start: Any, path: tuple[str, ...]) -> Any | None:
        node = start
        for name in path:
            node = await self.child(node, name)
            if node is None:
                return None
        return node


async def node_id(client: Any, text: str) -> Any:
    """The NodeId ``text`` names on this server: ``ns=``/``i=``/``s=``... as written, ``nsu=URI;...`` with URI
    looked up in the server's namespace array (:class:`MissingNodes` if it has no such namespace)."""
    from asyncua import ua

    parsed = ua.NodeId.from_string(text)
    uri = getattr(parsed, "NamespaceUri", None)
    if not uri:
        return ua.NodeId(parsed.Identifier, parsed.NamespaceIndex, parsed.NodeIdType)
    array = await client.get_namespace_array()
    if uri not in array:
        raise MissingNodes(f"the server has no namespace {uri!r} for {text} (it has {', '.join(array)})")
    return ua.NodeId(parsed.Identifier, array.index(uri), parsed.NodeIdType)


async def _exists(node: Any) -> bool:
    from asyncua import ua

    try:
        await node.read_browse_name()
    except ua.UaStatusCodeError:
        return False
    return True


async def locate(client: Any, node_map: NodeMap) -> dict[str, ResolvedNode | str]:
    """Each node of ``node_map`` (and the optional ones that exist) on the connected ``client``, or for a node
    that is not there, where it was looked for and why it was not found.  The furnace object missing is a
    :class:`MissingNodes` error (nothing below it can be looked for)."""
    browser = _Browser(await _namespace_index(client, node_map.namespace))
    furnace = await browser.walk(client.nodes.objects, node_map.object_path)
    if furnace is None:
        raise MissingNodes(f"the server has no object {'/'.join(node_map.object_path)} under Objects "
                           f"(mapping: {node_map.source})")
    found: dict[str, ResolvedNode | str] = {}
    for name, spec in node_map.nodes.items():
        if spec.node_id is not None:
            try:
                node = client.get_node(await node_id(client, spec.node_id))
            except MissingNodes as exc:
                found[name] = f"{node_map.describe(name)}: {exc}"
                continue
            node = node if await _exists(node) else None
        else:
            node = await browser.walk(furnace, spec.path or ())
        found[name] = node_map.describe(name) if node is None else \
            ResolvedNode(node, await node.read_data_type_as_variant_type())
    for name in OPTIONAL:
        node = await browser.walk(furnace, (name,))
        if node is not None:
            found[name] = ResolvedNode(node, await node.read_data_type_as_variant_type())
    return found


async def resolve(client: Any, node_map: NodeMap) -> dict[str, ResolvedNode]:
    """Every node of ``node_map`` on the connected ``client``; :class:`MissingNodes` if any is absent."""
    located = await locate(client, node_map)
    missing = [v for v in located.values() if isinstance(v, str)]
    if missing:
        raise MissingNodes("the furnace lacks " + "; ".join(missing))
    return {name: v for name, v in located.items() if isinstance(v, ResolvedNode)}
