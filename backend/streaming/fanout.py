"""Stream fan-out: every websocket client has its own bounded queue.

The run's driver publishes one serialised frame; :meth:`StreamHub.publish` puts it into
every subscriber's queue without waiting.  A full queue drops its *oldest* frame, so a
slow or stalled client only loses frames of its own and never slows the loop or the
other clients.  All methods run on the event loop thread.
"""

from __future__ import annotations

import asyncio
import logging
from dataclasses import dataclass, field

log = logging.getLogger(__name__)


@dataclass(eq=False)
class Subscriber:
    """One client's queue; ``None`` in the queue means: the stream has ended."""

    queue: asyncio.Queue[str | None]
    dropped: int = 0
    delivered: int = 0


@dataclass(eq=False)
class StreamHub:
    """The subscribers of one run's stream."""

    queue_frames: int = 4
    subscribers: set[Subscriber] = field(default_factory=set)
    latest: str | None = None
    closed: bool = False
    published: int = 0

    def subscribe(self) -> Subscriber:
        sub = Subscriber(asyncio.Queue(maxsize=self.queue_frames))
        if self.latest is not None:
            sub.queue.put_nowait(self.latest)
        if self.closed:
            self._offer(sub, None)
        self.subscribers.add(sub)
        return sub

    def unsubscribe(self, sub: Subscriber) -> None:
        self.subscribers.discard(sub)

    @staticmethod
    def _offer(sub: Subscriber, item: str | None) -> None:
        while True:
            try:
                sub.queue.put_nowait(item)
                return
            except asyncio.QueueFull:
                try:
                    sub.queue.get_nowait()
                    sub.dropped += 1
                except asyncio.QueueEmpty:  # pragma: no cover - only if another task drained it
                    pass

    def publish(self, frame: str) -> None:
        """Hand one frame to every client; never blocks."""
        self.latest = frame
        self.published += 1
        for sub in self.subscribers:
            self._offer(sub, frame)

    def close(self) -> None:
        """End of the run: each client gets the end marker after the frames it has queued."""
        if self.closed:
            return
        self.closed = True
        for sub in self.subscribers:
            self._offer(sub, None)
