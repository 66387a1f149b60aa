"""Start requests by id: the same ``POST /api/runs`` sent twice (a double click, a retry after a lost
answer) starts one run.

The dashboard sends a request id with each start (header ``Idempotency-Key``); :class:`StartRequests`
remembers the outcome of the last ``REMEMBERED`` ids.  A repeated id gets the first request's run
(or, while that one is still being checked, waits for it); an id whose start was refused is
forgotten, so the corrected request may use it again.

Example
-------
>>> import asyncio
>>> async def demo():
...     requests, calls = StartRequests(), []
...     async def make():
...         calls.append(1)
...         await asyncio.sleep(0.01)
...         return "run-1"
...     a, b = await asyncio.gather(requests.once("k", "{}", make), requests.once("k", "{}", make))
...     return a, b, len(calls)
>>> asyncio.run(demo())
(('run-1', False), ('run-1', True), 1)
"""

from __future__ import annotations

import asyncio
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from typing import Generic, TypeVar

T = TypeVar("T")
REMEMBERED = 256  # request ids kept


class RequestReused(ValueError):
    """The id came again with another body."""


class StartRequests(Generic[T]):
    """The outcomes of the latest start requests, by request id."""

    def __init__(self, remembered: int = REMEMBERED) -> None:
        self.remembered = remembered
        self._known: OrderedDict[str, tuple[str, asyncio.Future[T]]] = OrderedDict()

    async def once(self, request_id: str, body: str, make: Callable[[], Awaitable[T]]) -> tuple[T, bool]:
        """``(make()'s result, False)`` the first time an id comes, ``(that result, True)`` after; ``body``
        (the request as text) must be the same each time, else :class:`RequestReused`."""
        known = self._known.get(request_id)
        if known is not None:
            if known[0] != body:
                raise RequestReused(f"request id {request_id!r} was used for another scenario; send a new id")
            return await asyncio.shield(known[1]), True
        fut: asyncio.Future[T] = asyncio.get_running_loop().create_future()
        self._known[request_id] = (body, fut)
        while len(self._known) > self.remembered:
            self._known.popitem(last=False)
        try:
            result = await make()
        except BaseException as exc:
            self._known.pop(request_id, None)  # a refused start may be sent again once corrected
            fut.set_exception(exc)
            fut.exception()  # retrieved: a refusal nobody repeated is no asyncio warning
            raise
        fut.set_result(result)
        return result, False
