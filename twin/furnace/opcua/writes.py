"""What an OPC UA server of this project answers a client's Write (OPC UA Part 4, 7.34), on top of asyncua's.

asyncua answers a write to a node a user may not write with ``BadUserAccessDenied`` and a write its setter
clamped with plain ``Good``.  :func:`answer_writes` wraps a server's Write service so that a client learns what
became of its values: ``BadNotWritable`` for a read-only node of ours (whoever writes it), ``GoodClamped`` for
a value our setter clamped.  Used by the emulator (``furnace-twin emulate``) and the twin's results server.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any


def answer_writes(server: Any, name_of: Callable[[Any], str | None], writable: Callable[[str], bool],
                  clamped: set[Any]) -> None:
    """Wrap ``server``'s Write service: ``name_of(node_id)`` names our nodes (``None``: not ours),
    ``writable(name)`` says which clients may write, ``clamped`` collects the NodeIds our setters clamped during
    the request being served (cleared before each)."""
    from asyncua import ua

    service = server.iserver.attribute_service
    write = service.write

    async def answered(params: Any, *args: Any, **kwargs: Any) -> list[Any]:
        clamped.clear()
        results = await write(params, *args, **kwargs)
        out = []
        for wv, res in zip(params.NodesToWrite, results, strict=True):
            name = name_of(wv.NodeId)
            if (name is not None and res.value == ua.StatusCodes.BadUserAccessDenied
                    and wv.AttributeId == ua.AttributeIds.Value and not writable(name)):
                res = ua.StatusCode(ua.UInt32(ua.StatusCodes.BadNotWritable))
            elif res.is_good() and wv.NodeId in clamped:
                res = ua.StatusCode(ua.UInt32(ua.StatusCodes.GoodClamped))
            out.append(res)
        return out

    service.write = answered
